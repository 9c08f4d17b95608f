#!/usr/bin/env python3
"""Reads an MCAP log with the reference Python reader and decodes every message with the ROS 2
decoder, as ROS 2 tools and Foxglove would. Exit 1 if the file, a schema or a message is not
standard. Usage: check-mcap.py FILE.mcap [--require TOPIC ...]"""
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main() -> int:
    args = sys.argv[1:]
    if not args:
        print(__doc__)
        return 2
    path = args[0]
    required = args[args.index("--require") + 1:] if "--require" in args else []
    counts = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            if schema.encoding != "ros2msg" or channel.message_encoding != "cdr":
                print(f"{channel.topic}: not ros2msg/cdr ({schema.encoding}/{channel.message_encoding})")
                return 1
            counts[(channel.topic, schema.name)] = counts.get((channel.topic, schema.name), 0) + 1
            if schema.name == "sensor_msgs/msg/Image":
                assert len(decoded.data) == decoded.step * decoded.height, channel.topic
    for (topic, name), n in sorted(counts.items()):
        print(f"{n:6d}  {topic:32s} {name}")
    missing = [t for t in required if not any(t == topic for topic, _ in counts)]
    if missing:
        print("missing topics:", ", ".join(missing))
        return 1
    print(f"ok: {sum(counts.values())} messages decoded")
    return 0


if __name__ == "__main__":
    sys.exit(main())
