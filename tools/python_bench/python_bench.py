#!/usr/bin/env python3
"""python_bench: one-way bus latency, throughput and CPU of a Python subscriber against a C++
subscriber of the same 1.5 MB frames, in one run (docs/benchmarks/python.md).

    build/bin/probeless-python tools/python_bench/python_bench.py [--frames 600] [--burst 2000]
        [--json docs/benchmarks/python.json]

One publisher (this process, bus loans) sends 1024x512 rgb8 frames (1.5 MiB of pixels) to two
subscribers in their own processes at once: build/bin/python_bench_sub (C++) and this script with
--subscriber (Python, probeless.Subscriber). Phases: warm-up (30 frames, every slot written
once), paced (--frames at 30 Hz: latency and CPU per 30 fps stream), burst (--burst frames
back to back: throughput; a subscriber that falls behind loses frames to drop-oldest, counted).
Latency: CLOCK_MONOTONIC when the subscriber holds the image (C++: the message viewed; Python:
the numpy array of its pixels made) minus the bus's publish stamp. This is a benchmark, not a
test: the figures depend on the machine and its load, recorded with them in the JSON.
"""

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import time

import numpy as np

import probeless
from probeless import msgs

WIDTH, HEIGHT = 1024, 512  # rgb8: 1 572 864 bytes of pixels
TOPIC = "/python_bench/frames"


def subscriber_main(topic, out_path):
    """The Python subscriber: the same work as python_bench_sub.cpp."""
    sub = probeless.Subscriber(topic, msgs.Image, queue_depth=64, receive_history=False,
                               node_name="/python_bench_py")
    phases = {}
    current = None
    checksum = 0
    while True:
        sample = sub.take(timeout=30.0)
        if sample is None:
            print(f"[error] [python_bench] no frame for 30 s on {topic}", file=sys.stderr)
            return 2
        image = sample.msg
        pixels = image.pixels
        received = time.monotonic_ns()
        phase = image.header.frame_id
        if phase == "end":
            del pixels, image
            sample.release()
            break
        checksum += int(pixels[0, 0, 0])
        p = phases.setdefault(phase, {"latency_ns": []})
        if phase != current:
            p["dropped_before"] = sub.dropped
            p["first_wall"] = received
            p["first_cpu"] = time.process_time_ns()
            current = phase
        p["latency_ns"].append(received - sample.info.publish_mono_ns)
        p["last_wall"] = received
        p["last_cpu"] = time.process_time_ns()
        p["dropped"] = sub.dropped - p["dropped_before"]
        del pixels, image
        sample.release()
    out = {name: {"latency_ns": p["latency_ns"], "received": len(p["latency_ns"]),
                  "dropped": p["dropped"], "wall_s": (p["last_wall"] - p["first_wall"]) * 1e-9,
                  "cpu_s": (p["last_cpu"] - p["first_cpu"]) * 1e-9}
           for name, p in phases.items()}
    out["checksum"] = checksum
    pathlib.Path(out_path).write_text(json.dumps(out))
    return 0


def publish(pub, phase, count, rate_hz=None, fill=False):
    rate = probeless.Rate(rate_hz) if rate_hz else None
    for i in range(count):
        with pub.loan_image(WIDTH, HEIGHT, "rgb8") as loan:
            image = loan.msg
            image.header.frame_id = phase
            image.header.sequence = i + 1
            image.header.stamp_now()
            pixels = image.pixels
            if fill:
                pixels.fill(i % 256)
            else:
                pixels[0, 0, 0] = i % 256
            del pixels, image
            loan.publish()
        if rate:
            rate.sleep()


def summary(phase, frame_bytes):
    latency_us = np.asarray(phase["latency_ns"], dtype=np.float64) * 1e-3
    wall = phase["wall_s"]
    rate = (phase["received"] - 1) / wall if wall > 0 else 0.0
    return {
        "received": phase["received"],
        "dropped": phase["dropped"],
        "latency_us": {"median": float(np.median(latency_us)),
                       "p90": float(np.percentile(latency_us, 90)),
                       "p99": float(np.percentile(latency_us, 99)),
                       "max": float(latency_us.max())},
        "messages_per_s": rate,
        "mb_per_s": rate * frame_bytes / 1e6,
        "cpu_percent": 100.0 * phase["cpu_s"] / wall if wall > 0 else 0.0,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=600, help="paced frames at 30 Hz")
    parser.add_argument("--burst", type=int, default=2000, help="frames back to back")
    parser.add_argument("--json", help="write the results here")
    parser.add_argument("--subscriber", nargs=2, metavar=("TOPIC", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber:
        return subscriber_main(*args.subscriber)
    if args.frames < 10 or args.burst < 10:
        parser.error("--frames and --burst must be >= 10")

    bin_dir = pathlib.Path(probeless.__file__).resolve().parents[2] / "bin"
    os.environ.setdefault("PROBELESS_DOMAIN", f"python_bench{os.getpid()}")
    work = pathlib.Path(f"/tmp/python_bench.{os.getpid()}")
    work.mkdir(exist_ok=True)
    frame_bytes = msgs.Image.message_bytes_for(WIDTH, HEIGHT, "rgb8")
    pub = probeless.Publisher(TOPIC, msgs.Image, max_message_bytes=frame_bytes, slot_count=64,
                              node_name="/python_bench_pub")
    children = {
        "cpp": subprocess.Popen([str(bin_dir / "python_bench_sub"), TOPIC, str(work / "cpp.json")]),
        "python": subprocess.Popen([sys.executable, __file__, "--subscriber", TOPIC,
                                    str(work / "python.json")]),
    }
    deadline = time.monotonic() + 30
    while pub.subscriber_count < 2:
        if time.monotonic() > deadline:
            raise RuntimeError("python_bench: the subscribers did not join within 30 s")
        time.sleep(0.05)
    load_before = os.getloadavg()
    publish(pub, "warmup", 64, rate_hz=100, fill=True)
    time.sleep(0.5)
    publish(pub, "paced", args.frames, rate_hz=30)
    time.sleep(0.5)
    publish(pub, "burst", args.burst)
    time.sleep(1.0)
    publish(pub, "end", 3, rate_hz=30)
    for name, child in children.items():
        if child.wait(timeout=60) != 0:
            raise RuntimeError(f"python_bench: the {name} subscriber failed")
    raw = {name: json.loads((work / f"{name}.json").read_text()) for name in children}
    results = {
        "benchmark": "python_bench",
        "frame": {"width": WIDTH, "height": HEIGHT, "encoding": "rgb8",
                  "message_bytes": frame_bytes},
        "paced_hz": 30,
        "paced_frames": args.frames,
        "burst_frames": args.burst,
        "machine": {"cpus": os.cpu_count(), "load_1min_before": load_before[0],
                    "load_1min_after": os.getloadavg()[0], "python": platform.python_version(),
                    "kernel": platform.release()},
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    for name, data in raw.items():
        results[name] = {phase: summary(data[phase], frame_bytes) for phase in ("paced", "burst")}
    text = json.dumps(results, indent=2)
    print(text)
    if args.json:
        pathlib.Path(args.json).write_text(text + "\n")
    for name in children:
        (work / f"{name}.json").unlink()
    work.rmdir()
    return 0


if __name__ == "__main__":
    sys.exit(main())
