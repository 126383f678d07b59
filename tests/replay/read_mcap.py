#!/usr/bin/env python3
"""Reads an MCAP log with the reference Python packages (PyPI mcap + mcap-ros2-support), decoding
every ROS 2 message, and prints one line per topic: "<topic> <count> <schema>". Used by
replay_integration_test to show that converted logs open in Foxglove-compatible readers."""
import sys
from collections import Counter

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

counts = Counter()
schemas = {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for schema, channel, message, decoded in reader.iter_decoded_messages():
        counts[channel.topic] += 1
        schemas[channel.topic] = schema.name
        if schema.name == "sensor_msgs/msg/Image":
            assert len(decoded.data) == decoded.step * decoded.height, channel.topic
for topic in sorted(counts):
    print(topic, counts[topic], schemas[topic])
