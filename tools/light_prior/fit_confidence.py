#!/usr/bin/env python3
"""The scene light's confidence calibration (light::ScenePipelineOptions::confidence_knots,
docs/light.md "Confidence"): a reliability table of the dominant-direction error against the fit
confidence, from composite_eval runs.

  fit    tools/light_prior/fit_confidence.py fit RUN.json [RUN.json ...] [--bins 4]
         runs made with `--light-param raw_confidence:=true` (the fit confidence published as is)
         on the train / validation splits: prints the knots (the median fit confidence and the
         median error of each bin, errors made non-increasing) as the C++ default and the table.
  check  tools/light_prior/fit_confidence.py check RUN.json [RUN.json ...] [--bins 10]
         [--knots R,E,R,E,...]
         runs with the published (calibrated) confidence, e.g. on the test split, or raw runs with
         --knots (the calibration applied here as light::ConfidenceCalibration does): per confidence
         bin the median error against the expectation the confidence states (e = 10 deg x
         sqrt((1 - c) / c), light/fusion.h) and whether it is within --tolerance (0.25) of it.
         Exits 1 when a bin is outside.

Frames count when composite_eval scored their direction (direct / ambient >= 1 at the object:
`direction_error_deg` in `per_frame`). Bins are quantiles of the confidence (equal counts; frames of
equal confidence share a bin, so a bin may be larger and there may be fewer bins).
"""
import argparse
import json
import math
import statistics
import sys

REFERENCE_DEG = 10.0  # light::kConfidenceReferenceErrorDeg


def frames(paths):
    out = []
    for path in paths:
        with open(path) as f:
            run = json.load(f)
        for scene in run.get("scenes", []):
            for frame in scene.get("per_frame", []):
                error = frame.get("direction_error_deg")
                light = frame.get("ours_light")
                if error is None or light is None:
                    continue
                out.append((float(light["confidence"]), float(error), scene["name"]))
    if not out:
        sys.exit("fit_confidence: no frame with direction_error_deg and ours_light in " +
                 ", ".join(paths))
    return sorted(out, key=lambda r: r[0])  # by confidence only: ties keep the runs' order


def bins(rows, count):
    """Equal-count bins of rows sorted by confidence; frames of equal confidence share a bin."""
    count = max(1, min(count, len(rows)))
    out, start = [], 0
    for k in range(1, count + 1):
        end = max(start, k * len(rows) // count)
        while 0 < end < len(rows) and rows[end][0] == rows[end - 1][0]:
            end += 1
        if end > start:
            out.append(rows[start:end])
        start = end
    return out


def expected_error(confidence):
    if confidence <= 0:
        return math.inf
    c = min(confidence, 1.0)
    return REFERENCE_DEG * math.sqrt((1 - c) / c)


def fit(args):
    rows = frames(args.runs)
    table = []
    for part in bins(rows, args.bins):
        table.append([statistics.median(r[0] for r in part),
                      statistics.median(r[1] for r in part), len(part),
                      len(set(r[2] for r in part))])
    # Pool adjacent bins whose error rises with the confidence (isotonic, by frame counts).
    pooled = []
    for raw, error, n, scenes in table:
        pooled.append([raw * n, error * n, n, scenes])
        while len(pooled) > 1 and pooled[-1][1] / pooled[-1][2] > pooled[-2][1] / pooled[-2][2]:
            b = pooled.pop()
            a = pooled[-1]
            pooled[-1] = [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]]
    knots = [(raw / n, error / n) for raw, error, n, _ in pooled]
    print(f"{len(rows)} frames of {len(set(r[2] for r in rows))} scenes")
    print("| fit confidence (bin median) | median error | frames | scenes (with repeats) |")
    print("|---|---|---|---|")
    for raw, error, n, scenes in table:
        print(f"| {raw:.3f} | {error:.1f}° | {n} | {scenes} |")
    text = ", ".join(f"{raw:.3f}, {error:.1f}" for raw, error in knots)
    print(f"knots (after pooling): {{{text}}}")


def confidence(error_deg):
    """light::ConfidenceFromExpectedError: c = 1 / (1 + (e / 10 deg)^2)."""
    return 1 / (1 + (error_deg / REFERENCE_DEG) ** 2)


def calibrate(knots, raw):
    """light::ConfidenceCalibration::Apply: piecewise linear in the error, constant beyond."""
    pairs = list(zip(knots[0::2], knots[1::2]))
    if raw <= pairs[0][0]:
        return confidence(pairs[0][1])
    for (r0, e0), (r1, e1) in zip(pairs, pairs[1:]):
        if raw <= r1:
            return confidence(e0 + (raw - r0) / (r1 - r0) * (e1 - e0))
    return confidence(pairs[-1][1])


def check(args):
    rows = frames(args.runs)
    if args.knots:
        knots = [float(v) for v in args.knots.split(",")]
        if len(knots) < 2 or len(knots) % 2:
            sys.exit("fit_confidence: --knots needs pairs R,E,...")
        rows = sorted(((calibrate(knots, raw), error, name) for raw, error, name in rows),
                      key=lambda r: r[0])
    bad = 0
    print(f"{len(rows)} frames of {len(set(r[2] for r in rows))} scenes")
    print("| confidence bin | expected error | median error | ratio | within |")
    print("|---|---|---|---|---|")
    for part in bins(rows, args.bins):
        expected = statistics.median(expected_error(r[0]) for r in part)
        median = statistics.median(r[1] for r in part)
        ratio = median / expected if expected > 0 else math.inf
        ok = abs(ratio - 1) <= args.tolerance
        bad += not ok
        print(f"| {part[0][0]:.3f}–{part[-1][0]:.3f} | {expected:.1f}° | {median:.1f}° | "
              f"{ratio:.2f} | {'yes' if ok else 'no'} |")
    print(f"{bad} of {len(bins(rows, args.bins))} bins outside ±{args.tolerance:.0%}")
    return 1 if bad else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=["fit", "check"])
    parser.add_argument("runs", nargs="+", help="composite_eval --json outputs")
    parser.add_argument("--bins", type=int, default=None)
    parser.add_argument("--tolerance", type=float, default=0.25)
    parser.add_argument("--knots", help="check: apply these knots to raw confidences")
    args = parser.parse_args()
    if args.bins is None:
        args.bins = 4 if args.command == "fit" else 10
    if args.bins < 1:
        sys.exit("fit_confidence: --bins must be >= 1")
    if args.command == "fit":
        fit(args)
        return 0
    return check(args)


if __name__ == "__main__":
    sys.exit(main())
