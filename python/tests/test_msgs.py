"""probeless.msgs: every message type with its fields, in place."""

import numpy as np
import pytest

import probeless
from probeless import msgs


@pytest.mark.parametrize("cls", msgs.ALL, ids=lambda c: c.__name__)
def test_every_type_is_a_zeroed_struct_with_its_fields(cls):
    message = cls()
    assert cls.type_name == "probeless_msgs/" + cls.__name__
    assert message.as_bytes().size == cls.struct_bytes
    assert not message.as_bytes().any()
    assert message.writable
    as_dict = probeless.to_dict(message)
    assert list(as_dict) == list(cls.fields)
    assert cls.layout_hash != 0


def test_struct_sizes_match_the_cpp_layouts():
    sizes = {msgs.Header: 56, msgs.Image: 128, msgs.CameraInfo: 176, msgs.Pose: 176,
             msgs.ShLight: 384, msgs.FaceObservation: 13024, msgs.GeometryBuffer: 128,
             msgs.TransferBuffer: 128, msgs.TrackingStatus: 336, msgs.Ack: 176,
             msgs.PlayerControl: 72, msgs.AuxiliaryViews: 384, msgs.AuxiliaryView: 80,
             msgs.Vector3: 24, msgs.Quaternion: 32, msgs.RigidTransform: 56}
    assert {c: c.struct_bytes for c in sizes} == sizes
    assert set(sizes) == set(msgs.ALL)


def test_fields_write_the_bytes_in_place():
    light = msgs.ShLight(bands=3, confidence=0.5, units="linear")
    light.header.frame_id = "camera"
    light.header.stamp_ns = 123
    light.coefficients[0] = [1, 2, 3]
    light.dominant_direction = [0, 0, -1]
    raw = light.as_bytes()
    assert raw[:8].view(np.int64)[0] == 123
    assert bytes(raw[24:30]) == b"camera"
    assert raw[56:60].view(np.uint32)[0] == 3
    assert raw[60:64].view(np.uint32)[0] == 1  # ShLightUnits::kLinear
    assert raw[64:76].view(np.float32).tolist() == [1, 2, 3]
    assert light.coefficients.shape == (25, 3) and light.coefficients.dtype == np.float32
    assert light.dominant_direction.tolist() == [0, 0, -1]
    light.validate()


def test_copy_is_independent():
    light = msgs.ShLight(bands=2)
    copy = light.copy()
    copy.bands = 4
    assert light.bands == 2 and copy.bands == 4


def test_nested_structs_share_the_message_bytes():
    pose = msgs.Pose()
    pose.transform.rotation.w = 1.0
    pose.transform.translation.x = 2.0
    assert pose.transform.apply((1, 0, 0)) == [3.0, 0.0, 0.0]
    header = msgs.Header(sequence=7, frame_id="world")
    pose.header = header
    assert pose.header.sequence == 7 and pose.header.frame_id == "world"


@pytest.mark.parametrize("encoding,shape,dtype", [
    ("rgb8", (3, 4, 3), np.uint8), ("bgr8", (3, 4, 3), np.uint8), ("mono8", (3, 4), np.uint8),
    ("mono16", (3, 4), np.uint16), ("depth16", (3, 4), np.uint16),
    ("float32", (3, 4), np.float32), ("rgb32f", (3, 4, 3), np.float32)])
def test_image_pixels_by_encoding(encoding, shape, dtype):
    image = msgs.Image.create(4, 3, encoding)
    assert image.encoding == encoding
    assert image.pixels.shape == shape and image.pixels.dtype == dtype
    assert image.payload.size == image.step * image.height
    image.pixels[...] = 1
    assert image.pixels.sum() == np.prod(shape)


def test_payload_planes():
    g = msgs.GeometryBuffer.create(8, 6)
    assert g.depth.shape == (6, 8) and g.normals.shape == (6, 8, 3) and g.colour.shape == (6, 8, 3)
    g.depth[:] = 2.0
    g.validate()
    t = msgs.TransferBuffer.create(8, 6, 16)
    assert t.coefficients.shape == (6, 8, 16) and t.layout == "interleaved_float32"
    face = msgs.FaceObservation(sample_count=3)
    face.set_sample_valid(1, True)
    assert face.sample_valid_mask().tolist() == [False, True, False]
    assert face.valid_sample_count() == 1
    aux = msgs.AuxiliaryViews()
    assert len(aux.views) == 4
    aux.views[2].role = "top"
    assert aux.views[2].role == "top"


def test_bad_values_raise_one_line_errors():
    with pytest.raises(probeless.MessageError,
                       match=r"^frame_id 'x{40}' has 40 characters, at most 31 fit$"):
        msgs.Header().frame_id = "x" * 40
    with pytest.raises(ValueError,
                       match=r"^encoding: unknown value 'rgb9' \(expected invalid, rgb8, bgr8"):
        msgs.Image().encoding = "rgb9"
    with pytest.raises(probeless.MessageError, match="unknown image encoding 'yuv'"):
        msgs.Image.create(4, 4, "yuv")
    with pytest.raises(ValueError, match=r"ShLight.dominant_direction holds 3 values, got 2"):
        msgs.ShLight().dominant_direction = [1, 2]
    with pytest.raises(probeless.MessageError, match="bands 9 out of range 1..5"):
        msgs.ShLight(bands=9).validate()
    with pytest.raises(TypeError, match="probeless_msgs/ShLight has no field 'colour'"):
        msgs.ShLight(colour=1)
    with pytest.raises(probeless.MessageError, match="Image: invalid encoding 0"):
        msgs.Image().pixels
