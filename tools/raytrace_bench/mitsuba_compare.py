#!/usr/bin/env python3
"""Cross-checks raytrace::PathTrace against Mitsuba 3 (scalar_rgb) on an exported scene.

Test tooling only, not run by CI. Needs `pip install mitsuba numpy` (a venv is fine).

    build/bin/pathtrace_compare --out /tmp/ptc --scene interior --spp 256
    python3 tools/raytrace_bench/mitsuba_compare.py /tmp/ptc [--spp 1024]

Reads DIR/scene.json, DIR/<k>.obj and DIR/probeless.pfm written by pathtrace_compare, renders the
same scene with Mitsuba's path integrator (max_depth = max_bounces + 2: Mitsuba counts the
camera segment and the light segment; box pixel filter; the same tessellated meshes, Lambertian
albedo, delta directional / point lights, one-sided rectangle and sphere area emitters with a
black BSDF, a constant environment), writes DIR/mitsuba.pfm and prints the difference: the ratio
of the image means per channel and the mean absolute difference of 8x8-pixel block means
relative to the image mean (blocks average the noise of both estimators away).
"""
import argparse
import json
import os
import sys

import numpy as np


def read_pfm(path):
    with open(path, "rb") as f:
        if f.readline().strip() != b"PF":
            raise ValueError(f"{path}: not an RGB PFM")
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(height, width, 3)[::-1].astype(np.float64)  # PFM rows are bottom-up


def write_pfm(path, image):
    with open(path, "wb") as f:
        f.write(b"PF\n%d %d\n-1.0\n" % (image.shape[1], image.shape[0]))
        f.write(np.ascontiguousarray(image[::-1], dtype="<f4").tobytes())


def rgb(v):
    return {"type": "rgb", "value": [float(x) for x in v]}


def build(mi, desc, directory, spp):
    cam = desc["camera"]
    look = mi.ScalarTransform4f()
    to_world = look.look_at(origin=cam["eye"], target=cam["target"], up=cam["up"])
    scene = {
        "type": "scene",
        # rr_depth high: Russian roulette changes noise, not the expectation; keep it out.
        "integrator": {"type": "path", "max_depth": desc["max_bounces"] + 2, "rr_depth": 1000},
        "sensor": {
            "type": "perspective",
            "fov": cam["fov_x_deg"],
            "fov_axis": "x",
            "to_world": to_world,
            "film": {"type": "hdrfilm", "width": cam["width"], "height": cam["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "sky": {"type": "constant", "radiance": rgb(desc["sky"])},
    }
    black = {"type": "diffuse", "reflectance": rgb([0, 0, 0])}
    for i, o in enumerate(desc["objects"]):
        scene[f"object_{i}"] = {"type": "obj", "filename": os.path.join(directory, o["obj"]),
                                "face_normals": False,
                                "bsdf": {"type": "diffuse", "reflectance": rgb(o["albedo"])}}
    for i, d in enumerate(desc["directional"]):
        scene[f"sun_{i}"] = {"type": "directional", "direction": [-x for x in d["to_light"]],
                             "irradiance": rgb(d["irradiance"])}
    for i, p in enumerate(desc["point"]):
        scene[f"point_{i}"] = {"type": "point", "position": p["position"],
                               "intensity": rgb(p["intensity"])}
    for i, a in enumerate(desc["area"]):
        emitter = {"type": "area", "radiance": rgb(a["radiance"])}
        if a["shape"] == "rectangle":
            u, v = np.array(a["half_u"]), np.array(a["half_v"])
            n = np.cross(u, v)
            n /= np.linalg.norm(n)
            m = np.identity(4)
            m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u, v, n, a["centre"]
            scene[f"lamp_{i}"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(m),
                                  "emitter": emitter, "bsdf": black}
        else:
            scene[f"lamp_{i}"] = {"type": "sphere", "center": a["centre"], "radius": a["radius"],
                                  "emitter": emitter, "bsdf": black}
    return mi.load_dict(scene)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir")
    parser.add_argument("--spp", type=int, default=0, help="Mitsuba spp (default: scene.json's)")
    args = parser.parse_args()
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    with open(os.path.join(args.dir, "scene.json")) as f:
        desc = json.load(f)
    spp = args.spp or desc["spp"]
    ours = read_pfm(os.path.join(args.dir, "probeless.pfm"))
    theirs = np.array(mi.render(build(mi, desc, args.dir, spp)), dtype=np.float64)[:, :, :3]
    write_pfm(os.path.join(args.dir, "mitsuba.pfm"), theirs)
    if ours.shape != theirs.shape:
        sys.exit(f"image sizes differ: {ours.shape} vs {theirs.shape}")
    h, w = (ours.shape[0] // 8) * 8, (ours.shape[1] // 8) * 8

    def blocks(im):
        return im[:h, :w].reshape(h // 8, 8, w // 8, 8, 3).mean(axis=(1, 3))

    mean_ours, mean_theirs = ours.mean(axis=(0, 1)), theirs.mean(axis=(0, 1))
    block_diff = np.abs(blocks(ours) - blocks(theirs)).mean() / theirs.mean()
    flipped = np.abs(blocks(ours[:, ::-1]) - blocks(theirs)).mean() / theirs.mean()
    print(f"mitsuba {mi.__version__} scalar_rgb, {spp} spp, max_depth {desc['max_bounces'] + 2}")
    print("image mean  probeless " + " ".join(f"{x:.4f}" for x in mean_ours) +
          "  mitsuba " + " ".join(f"{x:.4f}" for x in mean_theirs))
    print("ratio probeless / mitsuba per channel: " +
          " ".join(f"{x:.4f}" for x in mean_ours / mean_theirs))
    print(f"8x8 block mean |difference| / image mean: {block_diff:.4f}"
          f" (mirrored image, as an orientation check: {flipped:.4f})")


if __name__ == "__main__":
    main()
