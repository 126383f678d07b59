"""A Python node for the tests: camera/image -> python/image, every pixel inverted (255 - v),
written into a bus loan. Params: queue_depth (4), delay_s (0: a sleep per frame), slots (8: of
its publisher). Logs the frames relayed and dropped at exit."""

import time

import numpy as np

import probeless
from probeless import msgs


def main():
    node = probeless.Node("relay")
    queue_depth = node.param("queue_depth", 4)
    delay_s = node.param("delay_s", 0.0)
    slots = node.param("slots", 8)
    state = {"publisher": None, "frames": 0}

    def on_image(sample):
        image = sample.msg
        if state["publisher"] is None:
            state["publisher"] = node.create_publisher(
                msgs.Image, "python/image", slot_count=slots,
                max_message_bytes=msgs.Image.message_bytes_for(image.width, image.height,
                                                               image.encoding))
        with state["publisher"].loan_image(image.width, image.height, image.encoding) as loan:
            loan.msg.header = image.header
            np.subtract(255, image.pixels, out=loan.msg.pixels)
            loan.publish()
        state["frames"] += 1
        if delay_s > 0:
            time.sleep(delay_s)

    images = node.create_subscription(msgs.Image, "camera/image", on_image,
                                      queue_depth=queue_depth)
    node.spin()
    node.info(f"relayed {state['frames']} frames, dropped {images.dropped}")


if __name__ == "__main__":
    probeless.run_main("relay", main)
