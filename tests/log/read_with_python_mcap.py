#!/usr/bin/env python3
"""Checks probeless MCAP files against the reference Python implementation (PyPI: mcap,
mcap-ros2-support), in both directions.

1. `log_ros2_sample write DIR` writes sample_{none,lz4,zstd}.mcap and expected.json (the values of
   the probeless messages that went in). Each file is read with mcap.reader.make_reader (CRCs
   validated) and mcap_ros2.decoder.DecoderFactory; every decoded ROS 2 message is compared field by
   field with expected.json (stamps, frame ids, image size/encoding/step/data, camera intrinsics,
   poses, and every probeless_msgs/msg type). The non-seeking reader (data section CRC), the
   Statistics record, the DataEnd CRC and the Footer's summary CRC are checked too.
2. This script writes MCAP files with mcap_ros2.writer (zstd, lz4, uncompressed) using the standard
   ROS 2 definitions; `log_ros2_sample read` decodes them with probeless::log and the values must
   come back.

Run by ctest (tests/log/CMakeLists.txt). Missing Python packages are a failure, not a skip.
"""

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import zlib

try:
    from mcap.reader import NonSeekingReader, make_reader
    from mcap.writer import CompressionType
    from mcap_ros2.decoder import DecoderFactory
    from mcap_ros2.writer import Writer as Ros2Writer
except ImportError as error:
    print(
        "read_with_python_mcap.py: FAILED: this test needs the Python packages 'mcap' and "
        "'mcap-ros2-support' (install them with: python3 -m pip install mcap mcap-ros2-support; "
        "tools/setup does): %s" % error,
        file=sys.stderr,
    )
    sys.exit(1)

ROS_ENCODINGS = {
    "rgb8": "rgb8",
    "bgr8": "bgr8",
    "mono8": "mono8",
    "mono16": "mono16",
    "depth16": "16UC1",
    "float32": "32FC1",
}
ROS_DISTORTION_MODELS = {"none": "", "plumb_bob": "plumb_bob",
                         "rational_polynomial": "rational_polynomial"}

failures = []
checks = [0]


def check(condition, what):
    checks[0] += 1
    if not condition:
        failures.append(what)


def check_eq(actual, expected, what):
    checks[0] += 1
    if actual != expected:
        failures.append("%s: got %r, expected %r" % (what, actual, expected))


def check_stamp(ros_header, header, what):
    stamp_ns = header["stamp_ns"]
    check_eq(ros_header.stamp.sec, stamp_ns // 1_000_000_000, what + " header.stamp.sec")
    check_eq(ros_header.stamp.nanosec, stamp_ns % 1_000_000_000, what + " header.stamp.nanosec")
    check_eq(ros_header.frame_id, header["frame_id"], what + " header.frame_id")


def check_full_header(ros, header, what):
    check_stamp(ros.header, header, what)
    check_eq(ros.stamp_mono_ns, header["stamp_mono_ns"], what + " stamp_mono_ns")
    check_eq(ros.sequence, header["sequence"], what + " sequence")


def check_pose(ros_pose, transform, what):
    position = ros_pose.position
    orientation = ros_pose.orientation
    check_eq([position.x, position.y, position.z], transform["translation"], what + " position")
    w, x, y, z = transform["rotation_wxyz"]
    check_eq([orientation.x, orientation.y, orientation.z, orientation.w], [x, y, z, w],
             what + " orientation (x, y, z, w)")


def check_message(ros, expected, what):
    f = expected["fields"]
    kind = expected["probeless_type"]
    if kind == "probeless_msgs/Image":
        check_stamp(ros.header, f["header"], what)
        check_eq(ros.height, f["height"], what + " height")
        check_eq(ros.width, f["width"], what + " width")
        check_eq(ros.step, f["step"], what + " step")
        check_eq(ros.encoding, ROS_ENCODINGS[f["encoding"]], what + " encoding")
        check_eq(ros.is_bigendian, 0, what + " is_bigendian")
        data = bytes(ros.data)
        check_eq(len(data), f["step"] * f["height"], what + " data length")
        check_eq(data.hex(), f["data_hex"], what + " data bytes")
    elif kind == "probeless_msgs/CameraInfo":
        check_stamp(ros.header, f["header"], what)
        check_eq(ros.height, f["height"], what + " height")
        check_eq(ros.width, f["width"], what + " width")
        check_eq(ros.distortion_model, ROS_DISTORTION_MODELS[f["distortion_model"]],
                 what + " distortion_model")
        check_eq(list(ros.d), f["distortion"], what + " d")
        fx, fy, cx, cy = f["fx"], f["fy"], f["cx"], f["cy"]
        check_eq(list(ros.k), [fx, 0, cx, 0, fy, cy, 0, 0, 1], what + " k")
        check_eq(list(ros.r), [1, 0, 0, 0, 1, 0, 0, 0, 1], what + " r")
        check_eq(list(ros.p), [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], what + " p")
        check_eq([ros.binning_x, ros.binning_y], [0, 0], what + " binning")
        check_eq([ros.roi.x_offset, ros.roi.y_offset, ros.roi.height, ros.roi.width,
                  ros.roi.do_rectify], [0, 0, 0, 0, False], what + " roi")
    elif kind == "probeless_msgs/Pose":
        check_stamp(ros.header, f["header"], what)
        check_eq(ros.header.frame_id, f["parent_frame_id"], what + " parent frame")
        check_pose(ros.pose, f["transform"], what + " pose")
    elif kind == "probeless_msgs/FaceObservation":
        check_full_header(ros, f["header"], what)
        check_eq(ros.face_detected, f["face_detected"], what + " face_detected")
        check_eq(list(ros.landmarks), f["landmarks"], what + " landmarks")
        check_pose(ros.head_pose, f["head_pose"], what + " head_pose")
        check_eq(ros.quality, f["quality"], what + " quality")
        check_eq(list(ros.sample_rgb), f["sample_rgb"], what + " sample_rgb")
        check_eq(list(ros.sample_normals), f["sample_normals"], what + " sample_normals")
        check_eq(list(ros.sample_valid), f["sample_valid"], what + " sample_valid")
    elif kind == "probeless_msgs/ShLight":
        check_full_header(ros, f["header"], what)
        check_eq(ros.bands, f["bands"], what + " bands")
        check_eq(list(ros.coefficients), f["coefficients"], what + " coefficients")
        check_eq(list(ros.dominant_direction), f["dominant_direction"],
                 what + " dominant_direction")
        check_eq(ros.intensity, f["intensity"], what + " intensity")
        check_eq(ros.confidence, f["confidence"], what + " confidence")
        check_eq(ros.units, f["units"], what + " units")
    elif kind == "probeless_msgs/GeometryBuffer":
        check_full_header(ros, f["header"], what)
        check_eq([ros.width, ros.height], [f["width"], f["height"]], what + " size")
        check_eq(list(ros.depth), f["depth"], what + " depth")
        check_eq(list(ros.normals), f["normals"], what + " normals")
        check_eq(bytes(ros.colour).hex(), f["colour_hex"], what + " colour")
    elif kind == "probeless_msgs/TransferBuffer":
        check_full_header(ros, f["header"], what)
        check_eq([ros.width, ros.height, ros.coefficient_count],
                 [f["width"], f["height"], f["coefficient_count"]], what + " size")
        check_eq(list(ros.coefficients), f["coefficients"], what + " coefficients")
    else:
        failures.append("%s: unexpected type %s" % (what, kind))


def check_crcs(path):
    """DataEnd and Footer CRCs recomputed with zlib."""
    data = open(path, "rb").read()
    magic = b"\x89MCAP0\r\n"
    check(data[:8] == magic and data[-8:] == magic, path + ": magic at both ends")
    footer = len(data) - 8 - 29
    opcode, length, summary_start, summary_offset_start, summary_crc = struct.unpack_from(
        "<BQQQI", data, footer)
    check_eq((opcode, length), (0x02, 20), path + " footer record")
    check(0 < summary_start < footer, path + ": summary_start inside the file")
    check(summary_start <= summary_offset_start < footer, path + ": summary_offset_start")
    check_eq(summary_crc, zlib.crc32(data[summary_start:footer + 9 + 16]), path + " summary CRC")
    data_end = summary_start - 13
    opcode, length, data_crc = struct.unpack_from("<BQI", data, data_end)
    check_eq((opcode, length), (0x0F, 4), path + " DataEnd record before the summary")
    check_eq(data_crc, zlib.crc32(data[:data_end]), path + " data section CRC")


def check_sample(path, expected):
    with open(path, "rb") as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        check_eq(header.profile, "ros2", path + " profile")
        summary = reader.get_summary()
        check(summary is not None, path + ": has a summary")
        check_eq(summary.statistics.message_count, len(expected), path + " statistics count")
        check(len(summary.chunk_indexes) > 1, path + ": several chunk indexes")
        check_eq(len(summary.chunk_indexes), summary.statistics.chunk_count,
                 path + " chunk index count")
        for schema in summary.schemas.values():
            check_eq(schema.encoding, "ros2msg", path + " schema encoding of " + schema.name)
        for channel in summary.channels.values():
            check_eq(channel.message_encoding, "cdr", path + " message encoding")
            check("probeless.type" in channel.metadata, path + ": channel metadata")
        decoded = list(reader.iter_decoded_messages(log_time_order=True))
        check_eq(len(decoded), len(expected), path + " message count")
        for index, ((schema, channel, message, ros), want) in enumerate(zip(decoded, expected)):
            what = "%s message %d (%s)" % (os.path.basename(path), index, want["topic"])
            check_eq(channel.topic, want["topic"], what + " topic")
            check_eq(schema.name, want["schema"], what + " schema")
            check_eq(message.log_time, want["log_time"], what + " log_time")
            check_eq(message.publish_time, want["log_time"] + 10, what + " publish_time")
            check_eq(message.sequence, want["sequence"], what + " sequence")
            check_message(ros, want, what)
    with open(path, "rb") as stream:

        class Unseekable:
            def __init__(self, inner):
                self.inner = inner

            def read(self, size=-1):
                return self.inner.read(size)

        streamed = NonSeekingReader(Unseekable(stream), validate_crcs=True)
        count = sum(1 for _ in streamed.iter_messages())
        check_eq(count, len(expected), path + " non-seeking reader message count")
    check_crcs(path)


# ---- Python -> C++ ----

TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
SEP = "=" * 80 + "\n"


def msgdef(main, deps):
    return main + "".join(SEP + "MSG: " + name + "\n" + text for name, text in deps)


IMAGE_DEF = msgdef(
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
    "uint32 step\nuint8[] data\n",
    [("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)])
POSE_DEF = msgdef(
    "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
    [("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME),
     ("geometry_msgs/Pose", "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"),
     ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
     ("geometry_msgs/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n")])
CAMERA_INFO_DEF = msgdef(
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
    "float64[9]  k\nfloat64[9]  r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
    "RegionOfInterest roi\n",
    [("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME),
     ("sensor_msgs/RegionOfInterest",
      "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n")])


def python_messages():
    """(topic, datatype, definition, message dict, log time, expected probeless JSON fields)."""
    out = []
    t0 = 1_690_000_000 * 1_000_000_000
    for i, (encoding, ros_encoding, bpp) in enumerate(
            [("rgb8", "rgb8", 3), ("depth16", "16UC1", 2), ("float32", "32FC1", 4),
             ("mono8", "mono8", 1)]):
        width, height, pad = 7 + i, 5, 2 * i
        step = width * bpp + pad * bpp
        data = bytes((j * 7 + i * 13) % 251 for j in range(step * height))
        if encoding == "float32":
            data = b"".join(struct.pack("<f", 0.25 * (j % 17)) for j in range(step * height // 4))
        stamp = t0 + i * 1_000_000 + 123
        frame = "cam_%d" % i
        message = {"header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9},
                              "frame_id": frame},
                   "height": height, "width": width, "encoding": ros_encoding,
                   "is_bigendian": 0, "step": step, "data": data}
        fields = {"header": {"stamp_ns": stamp, "stamp_mono_ns": 0, "sequence": 0,
                             "frame_id": frame},
                  "width": width, "height": height, "step": step, "encoding": encoding,
                  "data_hex": data.hex()}
        out.append(("/py/image_%d" % i, "sensor_msgs/msg/Image", IMAGE_DEF, message, stamp,
                    "probeless_msgs/Image", fields))
    for i in range(3):
        stamp = t0 + 10_000_000 + i
        q = [0.0, math.sin(0.1 * i), 0.0, math.cos(0.1 * i)]  # x, y, z, w
        message = {"header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9},
                              "frame_id": "world"},
                   "pose": {"position": {"x": 1.5 * i, "y": -2.0, "z": 0.125},
                            "orientation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]}}}
        fields = {"header": {"stamp_ns": stamp, "stamp_mono_ns": 0, "sequence": 0,
                             "frame_id": "world"},
                  "parent_frame_id": "world", "child_frame_id": "",
                  "transform": {"translation": [1.5 * i, -2.0, 0.125],
                                "rotation_wxyz": [q[3], q[0], q[1], q[2]]}}
        out.append(("/py/pose", "geometry_msgs/msg/PoseStamped", POSE_DEF, message, stamp,
                    "probeless_msgs/Pose", fields))
    stamp = t0 + 20_000_000
    d = [0.1, -0.2, 0.001, 0.002, 0.05]
    message = {"header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9},
                          "frame_id": "cam_0"},
               "height": 480, "width": 640, "distortion_model": "plumb_bob", "d": d,
               "k": [600.5, 0, 320.25, 0, 601.0, 240.75, 0, 0, 1],
               "r": [1, 0, 0, 0, 1, 0, 0, 0, 1],
               "p": [600.5, 0, 320.25, 0, 0, 601.0, 240.75, 0, 0, 0, 1, 0],
               "binning_x": 0, "binning_y": 0,
               "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0,
                       "do_rectify": False}}
    fields = {"header": {"stamp_ns": stamp, "stamp_mono_ns": 0, "sequence": 0,
                         "frame_id": "cam_0"},
              "width": 640, "height": 480, "fx": 600.5, "fy": 601.0, "cx": 320.25, "cy": 240.75,
              "distortion_model": "plumb_bob", "distortion": d, "depth_scale": 0}
    out.append(("/py/camera_info", "sensor_msgs/msg/CameraInfo", CAMERA_INFO_DEF, message, stamp,
                "probeless_msgs/CameraInfo", fields))
    return out


def python_to_cpp(tool, workdir):
    messages = python_messages()
    expected = sorted(messages, key=lambda m: m[4])
    for name, compression in [("zstd", CompressionType.ZSTD), ("lz4", CompressionType.LZ4),
                              ("none", CompressionType.NONE)]:
        path = os.path.join(workdir, "from_python_%s.mcap" % name)
        with open(path, "wb") as stream:
            writer = Ros2Writer(stream, chunk_size=4096, compression=compression)
            schemas = {}
            for topic, datatype, definition, message, stamp, _, _ in messages:
                if datatype not in schemas:
                    schemas[datatype] = writer.register_msgdef(datatype, definition)
                writer.write_message(topic, schemas[datatype], message, log_time=stamp,
                                     publish_time=stamp)
            writer.finish()
        out = os.path.join(workdir, "from_python_%s.json" % name)
        result = subprocess.run([tool, "read", path, out], capture_output=True, text=True)
        check_eq(result.returncode, 0, "log_ros2_sample read %s (stderr: %s)" %
                 (path, result.stderr.strip()))
        if result.returncode != 0:
            continue
        got = json.load(open(out))
        check_eq(len(got), len(expected), path + " message count read by C++")
        for index, (g, want) in enumerate(zip(got, expected)):
            what = "C++ read of %s message %d (%s)" % (os.path.basename(path), index, want[0])
            check_eq(g["topic"], want[0], what + " topic")
            check_eq(g["log_time"], want[4], what + " log_time")
            check_eq(g["probeless_type"], want[5], what + " type")
            check_eq(g["fields"], want[6], what + " fields")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--tool", required=True, help="path of the log_ros2_sample executable")
    parser.add_argument("--workdir", required=True, help="scratch directory")
    args = parser.parse_args()
    os.makedirs(args.workdir, exist_ok=True)

    result = subprocess.run([args.tool, "write", args.workdir], capture_output=True, text=True)
    if result.returncode != 0:
        print("read_with_python_mcap.py: FAILED: log_ros2_sample write: " + result.stderr,
              file=sys.stderr)
        return 1
    expected = json.load(open(os.path.join(args.workdir, "expected.json")))
    types = {e["probeless_type"] for e in expected}
    check_eq(len(types), 7, "probeless types in the sample")
    for name in ["none", "lz4", "zstd"]:
        check_sample(os.path.join(args.workdir, "sample_%s.mcap" % name), expected)
    python_to_cpp(args.tool, args.workdir)

    checked = len(expected) * 3
    if failures:
        for failure in failures[:50]:
            print("FAIL: " + failure, file=sys.stderr)
        print("read_with_python_mcap.py: FAILED: %d checks failed" % len(failures),
              file=sys.stderr)
        return 1
    print("read_with_python_mcap.py: %d messages in 3 files decoded by mcap-ros2-support match; "
          "Python-written files read back by probeless::log (%d checks passed)"
          % (checked, checks[0]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
