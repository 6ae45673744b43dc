"""The official MCAP ROS 2 decoder (mcap-ros2-support) reads the track `tnd recording track` wrote (track.mcap): one
geometry_msgs/msg/PoseWithCovarianceStamped per tracked frame, decoded from the definitions stored in the file, each
matching its row of track.csv (pose, stamp and the x, y, yaw covariance at indices 0, 1, 5 of the 6x6), with a
unit quaternion about z and a symmetric, positive-definite covariance.

Usage: python pose_track_check.py TRACK_DIR
"""

import csv
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(out: str) -> None:
    with open(f"{out}/track.csv", newline="") as f:
        rows = {int(r["stamp_ns"]): r for r in csv.DictReader(f) if r["cov_xx"]}
    seen = 0
    with open(f"{out}/track.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            assert schema.name == "geometry_msgs/msg/PoseWithCovarianceStamped", schema.name
            assert channel.topic == "/tnd/object_pose", channel.topic
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            assert stamp == message.log_time, (stamp, message.log_time)
            row = rows[stamp]
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            assert abs(math.hypot(q.x, q.y, q.z, q.w) - 1.0) < 1e-9 and q.x == q.y == 0.0, q
            yaw = 2.0 * math.atan2(q.z, q.w)
            d = (yaw - float(row["theta"]) + math.pi) % (2 * math.pi) - math.pi
            assert abs(p.x - float(row["x"])) < 1e-12 and abs(p.y - float(row["y"])) < 1e-12 and abs(d) < 1e-9
            c = list(msg.pose.covariance)
            assert len(c) == 36 and all(c[i * 6 + j] == c[j * 6 + i] for i in range(6) for j in range(6))
            for name, index in (("cov_xx", 0), ("cov_xy", 1), ("cov_xtheta", 5), ("cov_yy", 7), ("cov_thetatheta", 35)):
                assert c[index] == float(row[name]), (name, c[index], row[name])
            # The x, y, yaw block is positive definite: its leading minors are positive.
            a, b, e, dd, f_, g = c[0], c[1], c[5], c[7], c[11], c[35]
            m2 = a * dd - b * b
            m3 = a * (dd * g - f_ * f_) - b * (b * g - f_ * e) + e * (b * f_ - dd * e)
            assert a > 0 and m2 > 0 and m3 > 0, (a, m2, m3)
            seen += 1
    assert seen == len(rows) > 0, (seen, len(rows))
    print(f"{out}/track.mcap: mcap_ros2 decoded {seen} PoseWithCovarianceStamped, each its track.csv row")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
