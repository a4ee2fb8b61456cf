"""Read every message of a recording back, as ROS messages: the reading
recipe of docs/recording.md (the ``mcap`` reader with ``mcap_ros2``'s
decoder; both come with the ``[record]`` extra).

    python examples/read_recording.py run.mcap

prints each topic with its type and how many messages it holds."""

from __future__ import annotations

import sys
from collections import Counter

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(path: str) -> None:
    counts: Counter[tuple[str, str]] = Counter()
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _message, _ros_msg in reader.iter_decoded_messages():
            # _ros_msg has the message's fields as attributes (_ros_msg.pose.pose.position.x)
            assert schema is not None
            counts[(channel.topic, schema.name)] += 1
    for (topic, type_name), count in sorted(counts.items()):
        print(f"{topic} {type_name} {count}")


if __name__ == "__main__":
    main(sys.argv[1])
