"""Publisher / Subscriber on the shared-memory bus from Python: zero copy, deterministic release,
the bus's errors."""

import gc
import tracemalloc

import numpy as np
import pytest

import probeless
from probeless import msgs

from conftest import shm_segments

W, H = 640, 480
FRAME = msgs.Image.message_bytes_for(W, H, "rgb8")


def mapping_of(address):
    """The /proc/self/maps line of the mapping holding `address`."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            low, high = (int(x, 16) for x in line.split()[0].split("-"))
            if low <= address < high:
                return line.strip()
    return ""


def rss_anon_bytes():
    """This process's private resident memory (RssAnon: not the shared-memory slots)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("RssAnon:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no RssAnon in /proc/self/status")


def publish_frame(pub, value):
    with pub.loan_image(W, H, "rgb8") as loan:
        loan.msg.header.sequence = value
        loan.msg.pixels.fill(value % 256)
        return loan.publish()


def test_received_image_is_a_view_of_the_publishers_shared_memory(topic):
    pub = probeless.Publisher(topic, msgs.Image, max_message_bytes=FRAME)
    sub = probeless.Subscriber(topic, msgs.Image)
    with pub.loan_image(W, H, "rgb8") as loan:
        pixels = loan.msg.pixels
        pixels[:] = 9
        pixels[10, 20] = (1, 2, 3)
        written_at = pixels.ctypes.data
        del pixels
        loan.publish()
    with sub.take(timeout=2.0) as sample:
        image = sample.msg
        pixels = image.pixels
        assert pixels.shape == (H, W, 3) and pixels.dtype == np.uint8
        assert pixels[10, 20].tolist() == [1, 2, 3] and pixels[0, 0].tolist() == [9, 9, 9]
        assert not pixels.flags.owndata and not pixels.flags.writeable
        line = mapping_of(pixels.ctypes.data)
        segment = f"/dev/shm/probeless.{__import__('os').getuid()}.{probeless.current_domain()}.p."
        assert segment in line, line
        assert " rw-s " in line or " r--s " in line, line
        # The same bytes the loan wrote: one mapping of the slot per process, no copy.
        assert mapping_of(written_at).split()[-1] == line.split()[-1]
        assert sample.info.size == FRAME and sample.info.sequence == 1
        assert repr(sample) == f"<probeless.Sample probeless_msgs/Image #1 of {topic}>"
        del pixels, image


def test_release_refuses_while_a_view_lives_and_access_after_release_fails(topic):
    pub = probeless.Publisher(topic, msgs.ShLight)
    sub = probeless.Subscriber(topic, msgs.ShLight)
    pub.publish(msgs.ShLight(bands=3, confidence=0.25))
    sample = sub.take(timeout=2.0)
    coefficients = sample.msg.coefficients
    with pytest.raises(BufferError, match=r"^probeless: cannot release the sample of "
                       + topic + r": 1 numpy view\(s\) of it still exist"):
        sample.release()
    assert sample.msg.confidence == 0.25
    with pytest.raises(ValueError, match="read-only"):
        sample.msg.bands = 4
    del coefficients
    sample.release()
    assert sample.released
    with pytest.raises(ValueError, match=r"^probeless: the sample of " + topic + " was released$"):
        sample.msg.bands


def test_a_with_block_releases_the_slot_back_to_the_publisher(topic):
    pub = probeless.Publisher(topic, msgs.Image, max_message_bytes=FRAME, slot_count=2)
    sub = probeless.Subscriber(topic, msgs.Image, queue_depth=1)
    for i in range(20):  # two slots only: every sample must be released for the next loan
        publish_frame(pub, i)
        with sub.take(timeout=2.0) as sample:
            assert sample.msg.header.sequence == i
            assert int(sample.msg.pixels[5, 5, 0]) == i
        assert sample.released


def test_loans_refuse_publish_while_a_view_lives_and_drop_unpublished(topic):
    pub = probeless.Publisher(topic, msgs.Image, max_message_bytes=FRAME)
    sub = probeless.Subscriber(topic, msgs.Image)
    loan = pub.loan_image(W, H, "rgb8")
    pixels = loan.msg.pixels
    with pytest.raises(BufferError, match="cannot publish the loan on " + topic):
        loan.publish()
    del pixels
    loan.drop()
    with pytest.raises(ValueError, match="the loan on " + topic + " was released"):
        loan.publish()
    with pub.loan_image(W, H, "rgb8"):
        pass  # dropped at the end of the block
    assert sub.try_take() is None


def test_no_allocation_of_frame_size_per_message(topic):
    pub = probeless.Publisher(topic, msgs.Image, max_message_bytes=FRAME)
    sub = probeless.Subscriber(topic, msgs.Image, queue_depth=4)
    source = np.full((H, W, 3), 77, np.uint8)
    total = 0

    def one_frame():
        nonlocal total
        with pub.loan_image(W, H, "rgb8") as loan:
            np.copyto(loan.msg.pixels, source)
            loan.publish()
        with sub.take(timeout=2.0) as sample:
            total += int(sample.msg.pixels[H - 1, W - 1, 2])

    for _ in range(5):
        one_frame()
    gc.collect()
    tracemalloc.start()
    for _ in range(100):
        one_frame()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < W * H * 3 // 10, f"peak {peak} bytes traced while passing 100 frames"
    # Nor outside Python's allocator: the private (anonymous) resident memory stays put.
    before = rss_anon_bytes()
    for _ in range(100):
        one_frame()
    grown = rss_anon_bytes() - before
    assert grown < W * H * 3, f"RssAnon grew by {grown} bytes over 100 frames"
    assert total == 205 * 77


def test_wrong_type_is_the_bus_type_error(topic):
    images = probeless.Publisher(topic, msgs.Image, max_message_bytes=FRAME)
    expected = (f"^topic '{topic}' carries type 'probeless_msgs/Image' "
                f"\\(layout 0x{msgs.Image.layout_hash:016x}\\), not 'probeless_msgs/ShLight' "
                f"\\(layout 0x{msgs.ShLight.layout_hash:016x}\\)$")
    with pytest.raises(probeless.BusError, match=expected):
        probeless.Subscriber(topic, msgs.ShLight)
    node = probeless.Node("typed", argv=["typed"])
    with pytest.raises(probeless.BusError, match=expected):
        node.create_subscriber(msgs.ShLight, topic)
    pub = probeless.Publisher(topic + "_light", msgs.ShLight)
    with pytest.raises(TypeError, match=f"^probeless: publisher on {topic}_light carries "
                       "probeless_msgs/ShLight, not probeless_msgs/Pose$"):
        pub.publish(msgs.Pose())
    with pytest.raises(probeless.BusError, match="invalid|topic"):
        probeless.Subscriber("no_slash", msgs.ShLight)
    assert images.subscriber_count == 0  # the failed joins left nothing behind


def test_drops_history_and_the_held_sample_limit(topic):
    pub = probeless.Publisher(topic, msgs.ShLight, history=2)
    for i in range(3):
        pub.publish(msgs.ShLight(bands=1 + i))
    late = probeless.Subscriber(topic, msgs.ShLight, queue_depth=2)
    assert [late.take(0.5).msg.bands for _ in range(2)] == [2, 3]
    sub = probeless.Subscriber(topic, msgs.ShLight, queue_depth=2, receive_history=False)
    for i in range(5):
        pub.publish(msgs.ShLight(bands=1))
    assert sub.queued == 2 and sub.dropped == 3
    held = [sub.take(0.5) for _ in range(2)]
    for _ in range(14):
        pub.publish(msgs.ShLight(bands=1))
        held.append(sub.take(0.5))
    pub.publish(msgs.ShLight(bands=1))
    with pytest.raises(probeless.BusError, match="16"):
        sub.try_take()
    for sample in held:
        sample.release()
    assert sub.try_take() is not None


def test_introspection_sees_the_python_participants(topic):
    pub = probeless.Publisher(topic, msgs.ShLight, node_name="/py_pub")
    sub = probeless.Subscriber(topic, msgs.ShLight, node_name="/py_sub")
    [info] = [t for t in probeless.list_topics() if t["topic"] == topic]
    assert info["type"]["name"] == "probeless_msgs/ShLight"
    assert [p["node_name"] for p in info["publishers"]] == ["/py_pub"]
    assert [s["node_name"] for s in info["subscribers"]] == ["/py_sub"]
    assert pub.subscriber_count == 1 and sub.publisher_count == 1
    assert shm_segments()


def test_publish_copies_an_owned_message_with_its_payload(topic):
    pub = probeless.Publisher(topic, msgs.Image, max_message_bytes=msgs.Image.message_bytes_for(
        8, 4, "mono16"))
    sub = probeless.Subscriber(topic, msgs.Image)
    image = msgs.Image.create(8, 4, "mono16")
    image.pixels[:] = np.arange(32, dtype=np.uint16).reshape(4, 8)
    image.header.frame_id = "cam"
    assert pub.publish(image) == 1
    with sub.take(timeout=2.0) as sample:
        assert sample.msg.header.frame_id == "cam"
        assert sample.msg.pixels.tolist() == np.arange(32).reshape(4, 8).tolist()
        assert sample.msg.pixels.ctypes.data != image.pixels.ctypes.data
