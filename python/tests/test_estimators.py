"""The nodes' estimators on numpy arrays, MCAP errors, and the annotate example node."""

import numpy as np
import pytest

import probeless
from probeless import face_light, light, msgs

from conftest import SOURCE_DIR, python_script, subscribers_of, wait_until


def angle_deg(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def test_face_light_recovers_the_light_of_its_forward_model():
    estimator = face_light.FaceLightEstimator()
    truth = np.array([0.5, -0.3, -0.8]) / np.linalg.norm([0.5, -0.3, -0.8])
    rgb = estimator.predict(truth, [1.0, 0.9, 0.8], [0.2, 0.2, 0.2])
    assert rgb.shape == (estimator.sample_count, 3)
    estimate = estimator.estimate_rgb(rgb)
    assert estimate["channels"] == 3 and estimate["coefficients"].shape == (9, 3)
    assert angle_deg(estimate["dominant_direction"], truth) < 10
    linear = estimator.linear_light(rgb, None, estimate)
    assert linear["valid"]
    power = np.asarray(linear["power"])
    assert np.allclose(power / power[0], [1.0, 0.9, 0.8], atol=0.05)  # the light's colour
    # The same through a FaceObservation message, with half the samples invalid.
    observation = msgs.FaceObservation(face_detected=1, sample_count=estimator.sample_count)
    observation.sample_rgb[: estimator.sample_count] = rgb
    for i in range(0, estimator.sample_count, 2):
        observation.set_sample_valid(i, True)
    masked = estimator.estimate_observation(observation)
    assert masked["samples_used"] == observation.valid_sample_count()
    assert angle_deg(masked["dominant_direction"], truth) < 15


def test_face_light_errors_name_the_problem():
    estimator = face_light.FaceLightEstimator()
    with pytest.raises(probeless.FaceLightError,
                       match=r"^FaceLightEstimator: 9 RGB values, expected 3 x \d+ samples$"):
        estimator.estimate_rgb(np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match=r"valid mask has 2 entries for \d+ samples"):
        estimator.estimate_rgb(np.zeros((estimator.sample_count, 3), np.float32),
                               valid=np.array([True, False]))
    with pytest.raises(probeless.FaceLightError):
        face_light.FaceLightEstimator(model="/no/such/model.txt")


def synthetic_room(direction, width=320, height=240):  # noqa: C901
    """A camera 2 m in front of a wall with a floor and a ball, Lambertian under a directional
    light plus ambient: rgb8 (sRGB), depth in metres, intrinsics."""
    fx = fy = 0.9 * width
    cx, cy = (width - 1) / 2, (height - 1) / 2
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1)
    depth = np.full((height, width), 2.0)
    normals = np.zeros((height, width, 3))
    normals[...] = (0, 0, -1)
    floor = rays[..., 1] > 0.4 / 2.0  # the floor plane y = 0.4 m is nearer than the wall there
    depth[floor] = 0.4 / rays[floor][:, 1]
    normals[floor] = (0, -1, 0)
    # A ball of radius 0.35 m at (0.1, 0.05, 1.3) m.
    centre, radius = np.array([0.1, 0.05, 1.3]), 0.35
    b = rays @ centre
    rr = (rays * rays).sum(-1)
    disc = b * b - rr * (centre @ centre - radius * radius)
    hit = disc > 0
    t = (b - np.sqrt(np.where(hit, disc, 0))) / rr
    hit &= t < depth
    depth[hit] = t[hit]
    points = rays[hit] * t[hit][:, None]
    normals[hit] = (points - centre) / radius
    shade = 0.15 + 0.8 * np.clip(normals @ np.asarray(direction), 0, None)
    linear = np.clip(0.6 * shade, 0, 1)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    image = np.repeat((srgb * 255).round().astype(np.uint8)[..., None], 3, axis=2)
    return image, depth.astype(np.float32), (fx, fy, cx, cy)


def test_scene_pipeline_on_arrays_publishes_the_nodes_light():
    from_right = np.array([0.7, -0.5, -0.5]) / np.linalg.norm([0.7, -0.5, -0.5])
    image, depth, intrinsics = synthetic_room(from_right)
    pipeline = light.ScenePipeline(mode="depth", threads=2)
    result = pipeline.process(image, intrinsics, depth=depth, stamp_ns=5)
    assert result["valid"], result
    estimate = result["light"]
    assert isinstance(estimate, msgs.ShLight)
    estimate.validate()
    assert estimate.units == "linear" and estimate.bands == 4
    assert estimate.header.stamp_ns == 5 and 0 <= estimate.confidence <= 1
    assert 0 <= result["fit_confidence"] <= 1 and result["model"] == "distant"
    # The light follows the shading: from the right (+x), then from the left.
    assert estimate.dominant_direction[0] > 0.1
    left_image, _, _ = synthetic_room(from_right * [-1, 1, 1])
    millimetres = (depth * 1000).astype(np.uint16)
    info = msgs.CameraInfo(width=320, height=240, fx=intrinsics[0], fy=intrinsics[1],
                           cx=intrinsics[2], cy=intrinsics[3], depth_scale=0.001)
    left = pipeline.process(left_image, info, depth=millimetres, stamp_ns=6)
    assert left["valid"] and left["light"].dominant_direction[0] < -0.1
    with pytest.raises(probeless.LightError):
        pipeline.process(image, intrinsics, depth=depth[:120], stamp_ns=7)
    with pytest.raises(probeless.LightError, match="mode must be gbuffer or depth"):
        light.ScenePipeline(mode="lidar")


def test_mcap_errors_are_log_errors(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    with pytest.raises(probeless.LogError, match=str(bad)):
        probeless.log.McapReader(str(bad))


def test_annotate_example_draws_the_light_into_a_loan(processes):
    script = SOURCE_DIR / "python" / "examples" / "annotate.py"
    node = processes(python_script(script, "--ros-args", "-r", "__ns:=/annot"))
    images = probeless.Publisher("/annot/camera/image", msgs.Image,
                                 max_message_bytes=msgs.Image.message_bytes_for(320, 240, "rgb8"))
    lights = probeless.Publisher("/annot/scene/light", msgs.ShLight)
    out = probeless.Subscriber("/annot/camera/annotated", msgs.Image, queue_depth=4)
    assert wait_until(lambda: subscribers_of("/annot/camera/image", "/annot/annotate")
                      and subscribers_of("/annot/scene/light", "/annot/annotate"))
    sh = msgs.ShLight(bands=3, units="linear", confidence=1.0, intensity=1.0)
    sh.coefficients[0] = 0.5
    sh.coefficients[3] = -0.4  # Y_1,1 = -c x: light from +x
    sh.dominant_direction = [1, 0, 0]
    acks = probeless.Subscriber("/annot/annotate/ack", msgs.Ack, queue_depth=8)
    lights.publish(sh)
    with acks.take(timeout=10.0) as ack:
        assert ack.msg.topic == "/annot/scene/light"
    with images.loan_image(320, 240, "rgb8") as loan:
        loan.msg.header.sequence = 42
        loan.msg.pixels.fill(10)
        loan.publish()
    sample = out.take(timeout=10.0)
    assert sample is not None, (node.stop(), node.stderr)
    with sample:
        annotated = sample.msg
        assert (annotated.width, annotated.height, annotated.header.sequence) == (320, 240, 42)
        pixels = np.array(annotated.pixels)
    assert (pixels[:80, :160] != 10).any()           # the lat-long map
    assert pixels[120, 200].tolist() == [255, 255, 0]  # the arrow towards +x from the centre
    assert (pixels[200:, :100] == 10).all()           # the rest is the input
    assert node.stop() == 0
    assert "[info] [/annot/annotate] annotated 1 frames, dropped 0" in node.stderr


def test_scene_pipeline_equals_the_scene_light_node(processes):
    """The same frame through the C++ scene_light node and through light.ScenePipeline with its
    defaults gives the same light: the binding runs the node's library object and options."""
    from conftest import BIN_DIR

    truth = np.array([0.7, -0.5, -0.5]) / np.linalg.norm([0.7, -0.5, -0.5])
    image, depth, (fx, fy, cx, cy) = synthetic_room(truth)
    height, width = depth.shape
    millimetres = (depth * 1000).astype(np.uint16)
    stamp = 1_700_000_000_000_000_000
    node = processes([BIN_DIR / "scene_light", "--ros-args", "-r", "__ns:=/sl", "-p",
                      "mode:=depth", "-p", "publish_transfer:=false"])
    info_pub = probeless.Publisher("/sl/camera/camera_info", msgs.CameraInfo)
    image_pub = probeless.Publisher("/sl/camera/image", msgs.Image,
                                    max_message_bytes=msgs.Image.message_bytes_for(
                                        width, height, "rgb8"))
    depth_pub = probeless.Publisher("/sl/camera/depth", msgs.Image,
                                    max_message_bytes=msgs.Image.message_bytes_for(
                                        width, height, "depth16"))
    lights = probeless.Subscriber("/sl/scene/light", msgs.ShLight, queue_depth=4)
    acks = probeless.Subscriber("/sl/scene_light/ack", msgs.Ack, queue_depth=8)
    assert wait_until(lambda: subscribers_of("/sl/camera/depth", "/sl/scene_light"))
    info = msgs.CameraInfo(width=width, height=height, fx=fx, fy=fy, cx=cx, cy=cy,
                           depth_scale=0.001)
    info.header.stamp_ns = stamp
    info_pub.publish(info)
    with image_pub.loan_image(width, height, "rgb8") as loan:
        loan.msg.header.stamp_ns = stamp
        loan.msg.pixels[:] = image
        loan.publish()
    for _ in range(2):  # camera_info and image handled before the depth that triggers the frame
        with acks.take(timeout=10.0):
            pass
    with depth_pub.loan_image(width, height, "depth16") as loan:
        loan.msg.header.stamp_ns = stamp
        loan.msg.pixels[:] = millimetres
        loan.publish()
    sample = lights.take(timeout=60.0)
    assert sample is not None, (node.stop(), node.stderr)
    with sample:
        from_node = sample.msg.copy()
    ours = light.ScenePipeline(mode="depth").process(image, info, depth=millimetres,
                                                     stamp_ns=stamp)["light"]
    assert from_node.bands == ours.bands and from_node.units == ours.units
    np.testing.assert_allclose(ours.coefficients, from_node.coefficients, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(ours.dominant_direction, from_node.dominant_direction, atol=1e-5)
    assert ours.confidence == pytest.approx(from_node.confidence, abs=1e-6)
    assert ours.intensity == pytest.approx(from_node.intensity, rel=1e-5)
    assert node.stop() == 0
