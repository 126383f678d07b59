"""A Python node in a launch file among C++ nodes: 30 fps 640x480 frames without drops, lock-step
replay, and a kill -9 of the Python node reclaimed like any other participant."""

import re
import signal

import numpy as np
import pytest

import probeless
from probeless import msgs

from conftest import BIN_DIR, TESTS_DIR, python_script, shm_segments, subscribers_of, wait_until

W, H = 640, 480
FRAMES = 60


def frame_pixels(index):
    """The deterministic content of frame `index`."""
    y, x = np.mgrid[0:H, 0:W]
    base = (x + 2 * y + 7 * index) % 256
    return np.stack([base, (base + 85) % 256, (base + 170) % 256], axis=-1).astype(np.uint8)


@pytest.fixture(scope="module")
def frames_dir(tmp_path_factory):
    """FRAMES binary PPM files of 640x480 (played by the player's images source, rgb8)."""
    folder = tmp_path_factory.mktemp("frames")
    for i in range(FRAMES):
        with open(folder / f"frame{i:04d}.ppm", "wb") as f:
            f.write(f"P6 {W} {H} 255\n".encode())
            f.write(frame_pixels(i).tobytes())
    return folder


def launch(processes, *args):
    return processes([BIN_DIR / "probeless", "launch", TESTS_DIR / "frames.launch.yaml", *args])


def check_relayed(sample, index):
    """A /python/image sample is frame `index` inverted (its corners: the test keeps up with the
    stream; every pixel is compared in the recorded log)."""
    image = sample.msg
    assert (image.width, image.height, image.encoding) == (W, H, "rgb8")
    assert image.header.sequence == index + 1
    pixels = image.pixels
    for y, x in ((0, 0), (H - 1, W - 1)):
        base = (x + 2 * y + 7 * index) % 256
        assert pixels[y, x].tolist() == [255 - base, 255 - (base + 85) % 256,
                                         255 - (base + 170) % 256]


def test_thirty_fps_frames_through_a_python_node_without_drops(frames_dir, tmp_path, processes):
    out = tmp_path / "relayed.mcap"
    relayed = probeless.Subscriber("/python/image", msgs.Image, queue_depth=64)
    graph = launch(processes, f"frames:={frames_dir}", f"out:={out}")
    # The player starts paused: resume once the relay and the recorder are subscribed.
    assert wait_until(lambda: subscribers_of("/camera/image", "/relay")
                      and subscribers_of("/python/image", "/recorder"), timeout=20)
    control = probeless.Publisher("/player/control", msgs.PlayerControl)
    assert wait_until(lambda: control.subscriber_count > 0)
    control.publish(msgs.PlayerControl(command="resume"))
    stamps = []
    for i in range(FRAMES):
        sample = relayed.take(timeout=10.0)
        assert sample is not None, f"frame {i} never arrived; launch output: {graph.stderr}"
        with sample:
            check_relayed(sample, i)
            stamps.append(sample.info.publish_mono_ns)
    assert relayed.dropped == 0
    period = np.median(np.diff(stamps)) * 1e-9
    assert 0.025 < period < 0.042, f"median period {period * 1e3:.1f} ms, expected ~33"
    assert graph.stop(signal.SIGINT, timeout=30) == 0, graph.stderr
    assert re.search(r"\[info\] \[/relay\] relayed 60 frames, dropped 0",
                     graph.stderr), graph.stderr
    # The C++ recorder received every frame the Python node published.
    reader = probeless.log.McapReader(str(out))
    messages = list(reader.messages(topics=["/python/image"]))
    assert len(messages) == FRAMES
    for i, message in enumerate(messages):
        assert message.schema == "sensor_msgs/msg/Image"
        assert np.array_equal(message.msg.pixels, 255 - frame_pixels(i))
    frame_stamps = [m.msg.header.stamp_ns for m in messages]
    assert np.all(np.diff(frame_stamps) > 0)


def test_lock_step_replay_through_a_slow_python_node(frames_dir, tmp_path, processes):
    relayed = probeless.Subscriber("/python/image", msgs.Image, queue_depth=64)
    graph = launch(processes, f"frames:={frames_dir}", f"out:={tmp_path / 'x.mcap'}",
                   "player_args:=--fast --max-frames 20 --lockstep /relay", "relay_queue:=1",
                   "relay_delay:=0.03")
    for i in range(20):
        sample = relayed.take(timeout=20.0)
        assert sample is not None, f"frame {i} never arrived; launch output: {graph.stderr}"
        with sample:
            check_relayed(sample, i)
    assert graph.stop(signal.SIGINT, timeout=30) == 0, graph.stderr
    assert "[info] [/relay] relayed 20 frames, dropped 0" in graph.stderr, graph.stderr


def test_kill_9_of_a_python_node_is_reclaimed(processes):
    relay = processes(python_script(TESTS_DIR / "relay_node.py", "--ros-args", "-r",
                                    "camera/image:=/kill/image", "-r", "python/image:=/kill/out"))
    images = probeless.Publisher("/kill/image", msgs.Image,
                                 max_message_bytes=msgs.Image.message_bytes_for(W, H, "rgb8"))
    out = probeless.Subscriber("/kill/out", msgs.Image, queue_depth=4)
    assert wait_until(lambda: images.subscriber_count == 1)
    with images.loan_image(W, H, "rgb8") as loan:
        loan.publish()
    held = out.take(timeout=10.0)  # a sample of the Python node's slot, held across its death
    assert held is not None
    assert shm_segments(relay.pid)  # its publisher's data segment
    relay.stop(signal.SIGKILL)
    assert relay.popen.returncode == -signal.SIGKILL
    held.release()
    # Whoever touches the topics next reclaims the dead participant and unlinks its segments.

    def reclaimed():
        with images.loan_image(W, H, "rgb8") as touch:
            touch.publish()
        probeless.Subscriber("/kill/out", msgs.Image).close()  # a join runs maintenance
        listed = [p["pid"] for t in probeless.list_topics() if t["topic"].startswith("/kill/")
                  for p in t["publishers"] + t["subscribers"]]
        return relay.pid not in listed and not [
            name for name in shm_segments(relay.pid) if ".kill." in name]

    assert wait_until(reclaimed, timeout=10, period=0.1), (probeless.list_topics(),
                                                           shm_segments(relay.pid))
    # What only the dead node used (its ack topic, if no maintenance removed it yet) goes with the
    # final cleanup, as for a C++ node (`probeless clean`, the launch supervisor's).
    probeless.clean_dead_segments()
    assert not shm_segments(relay.pid)
    assert images.subscriber_count == 0
    # Restarting under the same names needs no cleanup.
    again = processes(python_script(TESTS_DIR / "relay_node.py", "--ros-args", "-r",
                                    "camera/image:=/kill/image", "-r", "python/image:=/kill/out"))
    assert wait_until(lambda: images.subscriber_count == 1)
    assert again.stop() == 0
