#!/usr/bin/env python3
"""Where the dominant-direction error comes from (docs/benchmarks/scene_light.md).

For every frame of composite_eval runs with direct/ambient >= --min-ratio and a true direction,
compares with truth.json's `direction_camera` (the sun or the lamp of largest irradiance):
  published      /scene/light's dominant_direction (what composite_eval scores)
  ours linear    the optimal linear direction (Sloan) of the published SH light's band 1
  ours delta     the direction of the best fit P delta(w - d) + free bands 0-1 to the published
                 light's bands 0-2 (band 2 carries the delta alone; band 1 picks its sign)
  probe linear   the same linear direction of the path-traced probe at the insertion (sh_camera)
  probe delta    the delta fit on the probe
Rows split the frames by whether that light reaches the object (probe delta within --lit-deg).
The probe columns bound what an exact SH light at the object could give under each readout.
Luminance = the mean of the r, g, b coefficients. SH convention of common/sh (real, with the
Condon-Shortley phase). Usage:
  direction_sources.py --scenes eval-world/validation RUN.json [RUN.json ...]
"""
import argparse
import json
import math
import os
import sys

import numpy as np


def basis(d):
    """Real SH of bands 0-2 of directions d (N, 3): the closed form of common/sh/sh.h (Condon-Shortley
    phase, index l(l+1)+m), as tools/light_prior/fit_light_prior.py."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([np.full_like(x, 0.28209479177), -0.48860251190 * y, 0.48860251190 * z,
                     -0.48860251190 * x, 1.09254843059 * x * y, -1.09254843059 * y * z,
                     0.31539156525 * (3 * z * z - 1), -1.09254843059 * x * z,
                     0.54627421529 * (x * x - y * y)], 1)


def fibonacci(n):
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = math.pi * (3 - math.sqrt(5)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


DIRECTIONS = fibonacci(6000)
BASIS = basis(DIRECTIONS)


def linear_direction(sh):
    v = np.array([-sh[3], -sh[1], sh[2]])
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def delta_direction(sh):
    """argmin over d of |band 2 - P Y_2(d)|^2 with P > 0 and d on band 1's side."""
    b2, y2 = np.asarray(sh[4:9]), BASIS[:, 4:9]
    dot = y2 @ b2
    power = dot / np.sum(y2 * y2, 1)
    residual = b2 @ b2 - power * dot
    usable = (power > 0) & (DIRECTIONS @ linear_direction(sh) > 0)
    if not usable.any():
        return linear_direction(sh)
    return DIRECTIONS[np.argmin(np.where(usable, residual, np.inf))]


def angle_deg(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return float("nan")
    return math.degrees(math.acos(float(np.clip(a @ b / (na * nb), -1, 1))))


COLUMNS = ["published", "ours linear", "ours delta", "probe linear", "probe delta"]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", required=True, help="the split's folder (truth.json per scene)")
    p.add_argument("--min-ratio", type=float, default=1.0, help="direct/ambient threshold (1)")
    p.add_argument("--lit-deg", type=float, default=15.0,
                   help="probe delta within this angle = the dominant light reaches the object (15)")
    p.add_argument("runs", nargs="+", help="composite_eval JSON files")
    a = p.parse_args()
    print("| run | frames | " + " | ".join(COLUMNS) + " |")
    print("|---|---|" + "---|" * len(COLUMNS))
    for run_path in a.runs:
        with open(run_path) as f:
            run = json.load(f)
        errors = []
        for scene in run["scenes"]:
            truth_path = os.path.join(a.scenes, scene["name"], "truth.json")
            if not os.path.exists(truth_path):
                sys.exit(f"direction_sources.py: {truth_path}: missing (wrong --scenes?)")
            with open(truth_path) as f:
                truth = {fr["timestamp"]: fr for fr in json.load(f)["frames"]}
            for pf in scene.get("per_frame", []):
                fr, light = truth.get(pf["timestamp"]), pf.get("ours_light")
                if fr is None or light is None or fr.get("direction_camera") is None:
                    continue
                if fr["direct_to_ambient"] < a.min_ratio or "sh_camera" not in fr:
                    continue
                want = fr["direction_camera"]
                ours = np.asarray(light["sh"], float).mean(1)
                probe = np.asarray(fr["sh_camera"], float).mean(1)
                errors.append([angle_deg(light["dominant_direction"], want),
                               angle_deg(linear_direction(ours), want),
                               angle_deg(delta_direction(ours), want),
                               angle_deg(linear_direction(probe), want),
                               angle_deg(delta_direction(probe), want)])
        e = np.array(errors, float)
        report(os.path.basename(run_path), e)
        if len(e):
            lit = e[:, 4] <= a.lit_deg
            report("  light reaches the object", e[lit])
            report("  object shadowed from it", e[~lit])


def report(name, e):
    """One table row: median / p90 of each column over the frames of e."""
    if len(e):
        cells = [f"{np.nanmedian(c):.1f}° / {np.nanpercentile(c, 90):.1f}°" for c in e.T]
    else:
        cells = ["—"] * len(COLUMNS)
    print(f"| {name} | {len(e)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
