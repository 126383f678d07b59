"""annotate: draws the estimated light onto the camera image (a Python node, docs/python.md).

Subscribes ``camera/image`` (rgb8 or bgr8) and ``scene/light`` (ShLight); publishes
``camera/annotated`` (rgb8, the image's size and header): the image with, in its top-left
corner, a lat-long map of the latest light's radiance (camera frame, up = -y, longitude 0 =
forward +z at the centre, +x to the right) with the dominant direction marked, and from the
image centre an arrow towards the dominant direction projected on the image plane, its length
scaled by the confidence. Frames are written straight into a bus loan; every input is
acknowledged on ``<node>/ack`` (lock-step replay).

Params: ``map_width`` (int, 160, pixels; 0 = no map), ``arrow_length`` (double, 120, pixels at
confidence 1), ``min_confidence`` (double, 0: lights below it are not drawn).
Exit: 0 on SIGINT/SIGTERM, 2 on bad params (one line on stderr), 1 otherwise.

    probeless-python python/examples/annotate.py --ros-args -r camera/image:=/camera/image_rect
"""

import numpy as np

import probeless
from probeless import msgs

# Real orthonormal SH to band 2, Condon-Shortley phase, index l(l+1)+m (docs/sh.md).
_SH_C = (0.282095, 0.488603, 1.092548, 0.315392, 0.546274)


def sh_basis9(directions):
    """The 9 basis values of band 0..2 for unit directions (N x 3) -> N x 9."""
    x, y, z = directions[:, 0], directions[:, 1], directions[:, 2]
    c = _SH_C
    return np.stack([
        np.full_like(x, c[0]), -c[1] * y, c[1] * z, -c[1] * x,
        c[2] * x * y, -c[2] * y * z, c[3] * (3 * z * z - 1), -c[2] * x * z,
        c[4] * (x * x - y * y)], axis=1)


def latlong_directions(width):
    """Unit directions (H x W x 3, H = W / 2) of a lat-long map in the camera frame."""
    height = width // 2
    lon = (np.arange(width) + 0.5) / width * 2 * np.pi - np.pi
    lat = np.pi / 2 - (np.arange(height) + 0.5) / height * np.pi
    lon, lat = np.meshgrid(lon, lat)
    return np.stack([np.cos(lat) * np.sin(lon), -np.sin(lat),
                     np.cos(lat) * np.cos(lon)], axis=-1).astype(np.float32)


def latlong_pixel(direction, width):
    """The map pixel (column, row) of a unit direction."""
    x, y, z = direction
    lon = np.arctan2(x, z)
    lat = np.arcsin(np.clip(-y, -1, 1))
    return (int((lon + np.pi) / (2 * np.pi) * width) % width,
            min(int((np.pi / 2 - lat) / np.pi * (width // 2)), width // 2 - 1))


def draw_line(pixels, start, end, colour, thickness=2):
    """Draws a segment (x, y pixel coordinates) into an H x W x 3 uint8 array in place."""
    height, width = pixels.shape[:2]
    steps = int(max(abs(end[0] - start[0]), abs(end[1] - start[1]))) + 1
    xs = np.linspace(start[0], end[0], steps).round().astype(int)
    ys = np.linspace(start[1], end[1], steps).round().astype(int)
    for dx in range(-thickness // 2, thickness - thickness // 2):
        for dy in range(-thickness // 2, thickness - thickness // 2):
            px, py = xs + dx, ys + dy
            keep = (px >= 0) & (px < width) & (py >= 0) & (py < height)
            pixels[py[keep], px[keep]] = colour


class Annotator:
    """The drawing, separate from the bus so that it can be used on any array."""

    def __init__(self, map_width, arrow_length):
        self.map_width = map_width - map_width % 2
        self.arrow_length = arrow_length
        self.map_basis = None
        if self.map_width > 0:
            dirs = latlong_directions(self.map_width)
            self.map_basis = sh_basis9(dirs.reshape(-1, 3))

    def draw(self, pixels, light):
        """Draws `light` (msgs.ShLight or None) onto `pixels` (H x W x 3 uint8) in place."""
        if light is None:
            return
        height, width = pixels.shape[:2]
        direction = np.asarray(light.dominant_direction, dtype=np.float64)
        coefficients = light.coefficients[:9].astype(np.float32)
        if self.map_basis is not None and self.map_width <= width and self.map_width // 2 <= height:
            radiance = np.clip(self.map_basis @ coefficients, 0, None)
            peak = float(radiance.max())
            if peak > 0:
                radiance = radiance / peak
            inset = (np.sqrt(radiance) * 255).astype(np.uint8)
            inset = inset.reshape(self.map_width // 2, self.map_width, 3)
            pixels[: self.map_width // 2, : self.map_width] = inset
            if np.linalg.norm(direction) > 0:
                col, row = latlong_pixel(direction, self.map_width)
                draw_line(pixels, (col - 4, row), (col + 4, row), (255, 0, 0))
                draw_line(pixels, (col, row - 4), (col, row + 4), (255, 0, 0))
        planar = direction[:2]
        if np.linalg.norm(planar) > 1e-6:
            tip = planar / np.linalg.norm(planar) * self.arrow_length * float(light.confidence)
            centre = (width / 2, height / 2)
            draw_line(pixels, centre, (centre[0] + tip[0], centre[1] + tip[1]), (255, 255, 0), 3)


def main():
    node = probeless.Node("annotate")
    map_width = node.param("map_width", 160)
    arrow_length = node.param("arrow_length", 120.0)
    min_confidence = node.param("min_confidence", 0.0)
    if map_width < 0 or arrow_length < 0:
        raise ValueError("map_width and arrow_length must be >= 0")
    annotator = Annotator(map_width, arrow_length)
    state = {"light": None, "publisher": None, "size": None, "frames": 0}

    def on_light(sample):
        light = sample.msg
        if light.confidence >= min_confidence:
            state["light"] = light.copy()  # the sample is released after this call

    def on_image(sample):
        image = sample.msg
        if image.encoding not in ("rgb8", "bgr8"):
            node.warn(f"camera/image is {image.describe()}: only rgb8 and bgr8 are annotated")
            return
        size = (image.width, image.height)
        if state["size"] != size:
            state["publisher"] = node.create_publisher(
                msgs.Image, "camera/annotated",
                max_message_bytes=msgs.Image.message_bytes_for(*size, "rgb8"), slot_count=8)
            state["size"] = size
        with state["publisher"].loan_image(*size, "rgb8") as loan:
            out = loan.msg
            out.header = image.header
            pixels = out.pixels
            source = image.pixels
            pixels[:] = source if image.encoding == "rgb8" else source[:, :, ::-1]
            annotator.draw(pixels, state["light"])
            del pixels, source  # the views must not outlive the slots
            loan.publish()
        state["frames"] += 1

    node.create_subscription(msgs.ShLight, "scene/light", on_light, queue_depth=4)
    images = node.create_subscription(msgs.Image, "camera/image", on_image, queue_depth=2)
    node.spin()
    node.info(f"annotated {state['frames']} frames, dropped {images.dropped}")


if __name__ == "__main__":
    probeless.run_main("annotate", main)
