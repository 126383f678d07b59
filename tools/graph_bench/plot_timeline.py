#!/usr/bin/python3
# plot_timeline.py: the timeline of one graph_bench run (docs/benchmarks/graph.md, issue #24).
#
#   /usr/bin/python3 tools/graph_bench/plot_timeline.py TIMELINE.json OUT.png [--from S] [--span S]
#
# TIMELINE.json is written by `graph_bench --timeline` (every handler call of every node of the
# first run). One row per node, a bar per handler call (coloured by its input topic), the player's
# /camera/image publishes as thin lines; the window starts --from seconds (default 3) after the
# first frame and is --span seconds long (default 1). Needs Debian's python3-matplotlib.
import argparse
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description="timeline of a graph_bench run")
    parser.add_argument("timeline")
    parser.add_argument("out")
    parser.add_argument("--from", dest="start", type=float, default=3.0)
    parser.add_argument("--span", type=float, default=1.0)
    args = parser.parse_args()
    if args.span <= 0:
        print("plot_timeline.py: --span expects seconds > 0", file=sys.stderr)
        sys.exit(2)
    with open(args.timeline) as f:
        t = json.load(f)
    camera = t.get("camera_s", [])
    if not camera:
        print("plot_timeline.py: no camera frames in " + args.timeline, file=sys.stderr)
        sys.exit(1)
    t0 = camera[0] + args.start
    t1 = t0 + args.span
    order = ["/rectify", "/fusion", "/scene_light", "/renderer"]
    names = [n for n in order if n in t["nodes"]] + sorted(n for n in t["nodes"] if n not in order)
    colours = plt.get_cmap("tab10")
    topic_colour = {}
    fig, ax = plt.subplots(figsize=(11, 0.7 * len(names) + 1.6))
    for row, name in enumerate(reversed(names)):
        node = t["nodes"][name]
        spans = {}
        for start, duration, index in node["calls"]:
            if start + duration < t0 or start > t1:
                continue
            topic = node["inputs"][index]
            spans.setdefault(topic, []).append(((start - t0) * 1e3, duration * 1e3))
        for topic, bars in spans.items():
            if topic not in topic_colour:
                topic_colour[topic] = colours(len(topic_colour) % 10)
            ax.broken_barh(bars, (row - 0.35, 0.7), facecolors=topic_colour[topic],
                          edgecolors="white", linewidth=0.3, label=topic)
    for c in camera:
        if t0 <= c <= t1:
            ax.axvline((c - t0) * 1e3, color="0.6", linewidth=0.6, zorder=0)
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles))
    ax.legend(unique.values(), unique.keys(), loc="upper center", bbox_to_anchor=(0.5, -0.18),
              ncol=4, fontsize=8, frameon=False)
    ax.set_yticks(range(len(names)))
    ax.set_yticklabels(list(reversed(names)))
    ax.set_xlim(0, args.span * 1e3)
    ax.set_xlabel("ms (grey lines: the player publishes a camera frame)")
    ax.set_title("graph_bench %s run: handler calls per node, %.1f-%.1f s after the first frame"
                 % (t.get("mode", "?"), args.start, args.start + args.span), fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
