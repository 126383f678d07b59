"""probeless.Node: the C++ node runtime's conventions from Python."""

import signal
import textwrap
import time

import pytest

import probeless
from probeless import msgs

from conftest import python_script, subscribers_of, wait_until

ROS_ARGS = ["prog", "own", "--ros-args", "-p", "rate_hz:=5", "-p", "label:=x", "-p",
            "gains:=[1.5, 2]", "-r", "chatter:=/remapped", "-r", "__ns:=/robot",
            "-r", "__node:=talker2"]


def test_ros_arguments_params_remaps_and_namespaces():
    node = probeless.Node("talker", argv=ROS_ARGS)
    assert node.name == "talker2" and node.namespace == "/robot"
    assert node.fully_qualified_name == "/robot/talker2"
    assert node.args == ["own"] and node.program == "prog"
    assert node.param("rate_hz", 30) == 5
    assert node.param("label", "y") == "x"
    assert node.param("gains", [0.0]) == [1.5, 2.0]
    assert node.param("unset", 2.5) == 2.5
    assert node.param("names", [], type="string_array") == []
    assert node.has_param_override("rate_hz") and not node.has_param_override("unset")
    declared = [(p.name, p.type, p.source) for p in node.declared_params()]
    assert ("rate_hz", "integer", "-p") in declared and ("unset", "double", "default") in declared
    assert node.resolve_topic_name("chatter") == "/remapped"
    assert node.resolve_topic_name("image") == "/robot/image"
    assert node.resolve_topic_name("~/state") == "/robot/talker2/state"
    assert node.ack_topic == "/robot/talker2/ack"
    publisher = node.create_publisher(msgs.ShLight, "chatter")
    assert publisher.topic == "/remapped"


def test_unknown_overrides_are_node_errors_naming_the_nearest_param():
    node = probeless.Node("talker", argv=["prog", "--ros-args", "-p", "rate_hx:=5"])
    node.param("rate_hz", 30.0)
    assert node.unused_param_overrides() == ["rate_hx"]
    with pytest.raises(probeless.NodeError,
                       match=r"^node '/talker': unknown parameter 'rate_hx' \(from -p\); "
                             r"did you mean 'rate_hz'\?$"):
        node.check_param_overrides()
    node.param("rate_hx", 1)
    node.check_param_overrides()


def test_bad_params_are_node_errors():
    node = probeless.Node("talker", argv=["prog", "--ros-args", "-p", "rate_hz:=fast"])
    with pytest.raises(probeless.NodeError, match="rate_hz"):
        node.param("rate_hz", 30)
    with pytest.raises(probeless.NodeError,
                       match=r"^node '/talker': required parameter 'absent' \(double\) is not set"):
        node.require_param("absent", float)
    with pytest.raises(probeless.NodeError):
        probeless.Node("talker", argv=["prog", "--ros-args", "-p"])
    with pytest.raises(probeless.NodeError, match="max_message_bytes"):
        node.create_publisher(msgs.Image, "image")


NODE_SCRIPT = textwrap.dedent("""
    import probeless
    from probeless import msgs

    def main():
        node = probeless.Node("listener")
        node.debug("debug line")
        got = []
        node.create_subscription(msgs.ShLight, "light", lambda s: got.append(s.msg.bands),
                                 queue_depth=8)
        print("ready", flush=True)
        node.spin()
        node.info(f"stopped after {len(got)} lights")
        return 0

    probeless.run_main("listener", main)
""")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_logging_spin_acks_and_clean_shutdown_on_signal(tmp_path, processes, sig):
    script = tmp_path / "listener.py"
    script.write_text(NODE_SCRIPT)
    ns = f"/ns{int(sig)}"
    child = processes(python_script(script, "--ros-args", "-r", f"__ns:={ns}",
                                    "--log-level", "debug"))
    assert child.popen.stdout.readline().strip() == "ready"
    acks = probeless.Subscriber(f"{ns}/listener/ack", msgs.Ack, queue_depth=8)
    assert wait_until(lambda: subscribers_of(f"{ns}/light", f"{ns}/listener"))
    lights = probeless.Publisher(f"{ns}/light", msgs.ShLight)
    sequences = [lights.publish(msgs.ShLight(bands=2)) for _ in range(3)]
    got = []
    for _ in sequences:
        ack = acks.take(timeout=5.0)
        assert ack is not None, (probeless.ok(), child.stop(), child.stderr)
        with ack:
            got.append((ack.msg.topic, ack.msg.publish_sequence))
    assert got == [(f"{ns}/light", s) for s in sequences]
    assert child.stop(sig) == 0
    assert f"[debug] [{ns}/listener] debug line" in child.stderr
    assert f"[info] [{ns}/listener] stopped after 3 lights" in child.stderr


def test_an_exception_in_a_callback_ends_spin_with_the_error(tmp_path, processes):
    script = tmp_path / "failing.py"
    script.write_text(NODE_SCRIPT.replace("got.append(s.msg.bands)", "1 / 0"))
    child = processes(python_script(script))
    assert child.popen.stdout.readline().strip() == "ready"
    assert wait_until(lambda: subscribers_of("/light", "/listener"))
    probeless.Publisher("/light", msgs.ShLight).publish(msgs.ShLight(bands=2))
    assert child.wait() == 1
    assert "[error] [listener] division by zero" in child.stderr


def test_help_and_bad_arguments_exit_like_a_cpp_node(tmp_path, processes):
    script = tmp_path / "listener.py"
    script.write_text(NODE_SCRIPT)
    child = processes(python_script(script, "--help"))
    assert child.wait() == 0 and "--ros-args" in child.stdout
    child = processes(python_script(script, "--ros-args", "-r", "bad"))
    assert child.wait() == 2
    assert child.stderr.startswith("[error] [listener] ")


ITERATE_SCRIPT = textwrap.dedent("""
    import probeless
    from probeless import msgs

    node = probeless.Node("iterate")
    sub = node.create_subscriber(msgs.ShLight, "light", queue_depth=8)
    print("ready", flush=True)
    bands = []
    for sample in sub:                 # until SIGTERM
        with sample:
            bands.append(sample.msg.bands)
            node.ack(sub, sample.info)
    print("bands", bands, flush=True)
""")


def test_iterating_a_subscriber_until_shutdown_with_explicit_acks(tmp_path, processes):
    script = tmp_path / "iterate.py"
    script.write_text(ITERATE_SCRIPT)
    child = processes(python_script(script, "--ros-args", "-r", "__ns:=/it"))
    assert child.popen.stdout.readline().strip() == "ready"
    acks = probeless.Subscriber("/it/iterate/ack", msgs.Ack, queue_depth=8)
    assert wait_until(lambda: subscribers_of("/it/light", "/it/iterate"))
    lights = probeless.Publisher("/it/light", msgs.ShLight)
    for bands in (1, 2, 3):
        lights.publish(msgs.ShLight(bands=bands))
    for sequence in (1, 2, 3):
        with acks.take(timeout=5.0) as ack:
            assert ack.msg.publish_sequence == sequence
    assert child.stop(signal.SIGTERM) == 0
    assert "bands [1, 2, 3]" in child.stdout


def test_ctrl_c_interrupts_a_take_without_a_node(tmp_path, processes):
    script = tmp_path / "bare.py"
    script.write_text(textwrap.dedent("""
        import probeless
        from probeless import msgs

        sub = probeless.Subscriber("/bare", msgs.ShLight)
        try:
            # Inside the try: a SIGINT that lands before take() blocks (a loaded machine) must
            # not escape as an uncaught KeyboardInterrupt.
            print("ready", flush=True)
            sub.take()                      # no timeout, Python's own SIGINT handler
        except KeyboardInterrupt:
            print("interrupted", flush=True)
    """))
    child = processes(python_script(script))
    assert child.popen.stdout.readline().strip() == "ready"
    time.sleep(0.5)  # let take() block, so that it is what the signal interrupts
    assert child.stop(signal.SIGINT, timeout=5) == 0
    assert "interrupted" in child.stdout
