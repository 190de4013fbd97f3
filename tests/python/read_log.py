#!/usr/bin/env python3
"""Decode every channel of an auvnav log with the third-party Python MCAP reader.

Proof that logs written by auvnav are readable without auvnav's code: the `mcap` package reads the
container and `mcap-ros2-support` decodes each message from the channel's ros2msg schema.
Prints a JSON summary (messages per topic, first message's fields) and exits non-zero if a channel
cannot be decoded, a channel has no message, or a message's host time differs from its log time.
"""
import json
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(path: str) -> int:
    counts = {}
    first = {}
    errors = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            print(json.dumps({"error": "no summary (file not finished)"}))
            return 1
        header = [m for m in reader.iter_metadata() if m.name == "auvnav.header"]
        if not header:
            errors.append("no auvnav.header metadata record")
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if decoded.host_time_ns != message.log_time:
                errors.append(f"{channel.topic}: host_time_ns != log_time")
            if channel.topic not in first:
                fields = {}
                for name in decoded.__slots__:
                    value = getattr(decoded, name)
                    if isinstance(value, float) and not math.isfinite(value):
                        errors.append(f"{channel.topic}.{name} is not finite")
                    fields[name] = value if not isinstance(value, (list, tuple)) else list(value)
                first[channel.topic] = fields
        for channel in summary.channels.values():
            if counts.get(channel.topic, 0) == 0:
                errors.append(f"channel {channel.topic} has no decodable message")
    print(json.dumps({"messages": counts, "first": first,
                      "header": header[0].metadata if header else None,
                      "errors": errors}, default=str))
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
