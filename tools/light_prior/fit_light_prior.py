#!/usr/bin/env python3
"""Fits the scene light prior (light::LightPrior, docs/light.md "Light prior") on a split of the
evaluation world: the zonal Legendre ratios z_l / z_0 (l = 1, 2) of the true light about the up
direction, averaged over every frame with SH truth.

  tools/light_prior/fit_light_prior.py eval-world/train [--up 0,1,0] [--json out.json]

Reads each scene's truth.json (sh_camera, camera frame, msgs SH convention) and groundtruth.txt
(TUM, camera -> world, optical frame); `--up` is the world's up (the generator's is +y). The
luminance of the light is used (Rec. 709 weights). Prints the mean and median ratios and the
number of frames; the node's prior_z1 / prior_z2 defaults are the means on the train split.
"""
import argparse
import json
import math
import os
import statistics
import sys


def basis(d):
    """Real SH of bands 0-2 (Condon-Shortley phase, index l(l+1)+m), as probeless/sh/sh.h."""
    x, y, z = d
    return [0.28209479177, -0.48860251190 * y, 0.48860251190 * z, -0.48860251190 * x,
            1.09254843059 * x * y, -1.09254843059 * y * z, 0.31539156525 * (3 * z * z - 1),
            -1.09254843059 * x * z, 0.54627421529 * (x * x - y * y)]


def rotation(q):
    """Row-major rotation of the unit quaternion (qx, qy, qz, qw)."""
    x, y, z, w = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


def frames(split, up_world):
    for name in sorted(os.listdir(split)):
        folder = os.path.join(split, name)
        truth_path = os.path.join(folder, "truth.json")
        if not os.path.isfile(truth_path):
            continue
        poses = {}
        with open(os.path.join(folder, "groundtruth.txt")) as f:
            for line in f:
                fields = line.split()
                if not fields or fields[0].startswith("#"):
                    continue
                if len(fields) != 8:
                    sys.exit(f"{folder}/groundtruth.txt: expected 8 fields, got {len(fields)}")
                poses[fields[0]] = [float(v) for v in fields[4:8]]
        with open(truth_path) as f:
            truth = json.load(f)
        for frame in truth.get("frames", []):
            sh = frame.get("sh_camera")
            if not sh or len(sh) < 9 or frame.get("timestamp") not in poses:
                continue
            r = rotation(poses[frame["timestamp"]])  # camera -> world
            up = [sum(r[i][j] * up_world[i] for i in range(3)) for j in range(3)]  # R^T up
            yield [0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2] for c in sh[:9]], up


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("split", help="folder of scene folders (e.g. eval-world/train)")
    parser.add_argument("--up", default="0,1,0", help="the world's up direction (default 0,1,0)")
    parser.add_argument("--json", help="also write the figures here")
    args = parser.parse_args()
    try:
        up = [float(v) for v in args.up.split(",")]
    except ValueError:
        sys.exit(f"--up: expected three numbers x,y,z, got '{args.up}'")
    n = math.sqrt(sum(v * v for v in up)) if len(up) == 3 else 0
    if not n > 0:
        sys.exit(f"--up: expected a non-zero 3-vector, got '{args.up}'")
    up = [v / n for v in up]
    if not os.path.isdir(args.split):
        sys.exit(f"{args.split}: not a folder")
    ratios = {1: [], 2: []}
    for g, up_camera in frames(args.split, up):
        y = basis(up_camera)
        z0 = g[0] * y[0]
        if not z0 > 0:
            continue
        ratios[1].append(sum(g[k] * y[k] for k in (1, 2, 3)) / z0)
        ratios[2].append(sum(g[k] * y[k] for k in range(4, 9)) / z0)
    if not ratios[1]:
        sys.exit(f"{args.split}: no frame with sh_camera truth and a pose")
    out = {"split": args.split, "frames": len(ratios[1])}
    for l in (1, 2):
        out[f"z{l}_mean"] = statistics.mean(ratios[l])
        out[f"z{l}_median"] = statistics.median(ratios[l])
    print(json.dumps(out, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
