"""The official MCAP ROS 2 decoder (mcap-ros2-support) reads every message of a recording `tnd recording simulate`
wrote: depth images (16UC1 / 32FC1) or point clouds, and the object's PoseStamped. It knows no ROS types: it decodes
from the message definitions stored in the file, so a definition that leaves out a nested type fails here.

Usage: python mcap_ros2_check.py REC.mcap FRAMES [more REC.mcap FRAMES ...]
"""

import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def check(path: str, frames: int) -> None:
    counts: dict[str, int] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            assert stamp == message.log_time, (path, channel.topic, stamp, message.log_time)
            if schema.name == "sensor_msgs/msg/Image":
                assert msg.encoding in ("16UC1", "32FC1"), msg.encoding
                assert (msg.width, msg.height) == (224, 171), (msg.width, msg.height)
                assert len(msg.data) == msg.step * msg.height
            elif schema.name == "sensor_msgs/msg/PointCloud2":
                assert [fld.name for fld in msg.fields] == ["x", "y", "z"]
                assert len(msg.data) == msg.point_step * msg.width > 0
            elif schema.name == "geometry_msgs/msg/PoseStamped":
                q = msg.pose.orientation
                assert abs(math.hypot(q.x, q.y, q.z, q.w) - 1.0) < 1e-9, q
                assert msg.pose.position.z == 0.0
            else:
                raise AssertionError(f"{path}: unexpected schema {schema.name}")
    depth = [n for t, n in counts.items() if "pose" not in t]
    assert depth == [frames], (path, counts)
    assert sum(counts.values()) == 2 * frames, (path, counts)
    print(f"{path}: mcap_ros2 decoded {counts}")


if __name__ == "__main__":
    args = sys.argv[1:]
    if not args or len(args) % 2:
        sys.exit(__doc__)
    for i in range(0, len(args), 2):
        check(args[i], int(args[i + 1]))
