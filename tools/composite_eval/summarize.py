#!/usr/bin/env python3
"""Markdown tables of composite_eval runs (docs/benchmarks/composite.md): the summary per run, the
per-scene ratios ours/oracle, ours/baseline and the effect ratio, and the figures by scene kind
(room and light type from each scene's scene.json, when the folder holds generated scenes).

  tools/composite_eval/summarize.py --scenes eval-world/test gbuffer.json [depth.json ...]
"""
import argparse
import json
import os
import statistics
import sys


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def p90(values):
    values = sorted(v for v in values if v is not None)
    if not values:
        return None
    return values[min(len(values) - 1, int(round(0.9 * (len(values) - 1))))]


def fmt(v, digits=3):
    return "—" if v is None else f"{v:.{digits}f}"


def ratios(scenes, a, b):
    return [s[a] / s[b] for s in scenes if s.get(a) is not None and s.get(b)]


def directions(scenes):
    return [s["direction_error_deg_median"] for s in scenes
            if s.get("direction_error_deg_median") is not None]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", help="the scene folders' parent (for scene.json kinds)")
    parser.add_argument("runs", nargs="+", help="composite_eval --json outputs")
    args = parser.parse_args()
    runs = []
    for path in args.runs:
        try:
            with open(path) as f:
                runs.append((path, json.load(f)))
        except (OSError, json.JSONDecodeError) as e:
            sys.exit(f"{path}: cannot read a composite_eval JSON ({e})")
    print("| run | scenes | ours SI med / p90 | oracle SI med | baseline SI med | ours/oracle | "
          "ours/baseline (ours better) | effect ours/baseline | direction med / p90 (scenes) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path, run in runs:
        scenes = run["scenes"]
        obj = [s for s in scenes if s.get("ours_si_rmse_object") is not None]
        better = sum(1 for s in obj if s.get("baseline_si_rmse_object") is not None and
                     s["ours_si_rmse_object"] < s["baseline_si_rmse_object"])
        d = directions(scenes)
        print(f"| {os.path.basename(path)} ({run.get('mode', '?')}) | {len(scenes)} | "
              f"{fmt(median([s['ours_si_rmse_object'] for s in obj]))} / "
              f"{fmt(p90([s['ours_si_rmse_object'] for s in obj]))} | "
              f"{fmt(median([s.get('oracle_si_rmse_object') for s in obj]))} | "
              f"{fmt(median([s.get('baseline_si_rmse_object') for s in obj]))} | "
              f"{fmt(median(ratios(obj, 'ours_si_rmse_object', 'oracle_si_rmse_object')), 2)} | "
              f"{fmt(median(ratios(obj, 'ours_si_rmse_object', 'baseline_si_rmse_object')), 2)} "
              f"({better} of {len(obj)}) | "
              f"{fmt(median(ratios(obj, 'ours_rmse_effect', 'baseline_rmse_effect')), 2)} | "
              f"{fmt(median(d), 1)}° / {fmt(p90(d), 1)}° ({len(d)}) |")
    if not args.scenes:
        return
    path, run = runs[0]
    kinds = {}
    for s in run["scenes"]:
        meta_path = os.path.join(args.scenes, s["name"], "scene.json")
        try:
            with open(meta_path) as f:
                meta = json.load(f)
        except (OSError, json.JSONDecodeError):
            continue
        kinds.setdefault(f"{meta.get('room', '?')} / {meta.get('light_type', '?')}", []).append(s)
    print(f"\nBy scene kind ({os.path.basename(path)}, medians over scenes):\n")
    print("| room / light | scenes | ours SI | oracle SI | baseline SI | ours/baseline | "
          "direction (scenes) |")
    print("|---|---|---|---|---|---|---|")
    for kind in sorted(kinds):
        scenes = kinds[kind]
        d = directions(scenes)
        print(f"| {kind} | {len(scenes)} | "
              f"{fmt(median([s.get('ours_si_rmse_object') for s in scenes]))} | "
              f"{fmt(median([s.get('oracle_si_rmse_object') for s in scenes]))} | "
              f"{fmt(median([s.get('baseline_si_rmse_object') for s in scenes]))} | "
              f"{fmt(median(ratios(scenes, 'ours_si_rmse_object', 'baseline_si_rmse_object')), 2)} | "
              f"{fmt(median(d), 1)}° ({len(d)}) |")


if __name__ == "__main__":
    main()
