#!/usr/bin/env python3
"""Interop with a DDS implementation that is not ours: Eclipse Cyclone DDS (PyPI `cyclonedds`)
plays the robot's drivers for `spomp run`.

It publishes odometry, a panorama (depth + labels) and a ground-truth pose in the standard ROS 2
types, encoded by Cyclone from its own definitions of them, and subscribes to spomp's velocity
commands. It passes when spomp decodes every input (its report counts them, none malformed) and
commands the robot forward toward its goal, decoded by Cyclone.

Loopback only: Cyclone is bound to 127.0.0.1 without multicast, spomp runs with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, on a domain of this test's own.

    python3 scripts/cyclonedds-interop.py target/debug/spomp
"""

import json
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field

DOMAIN = 150 + os.getpid() % 50
os.environ["CYCLONEDDS_URI"] = (
    "<CycloneDDS><Domain id='any'><General><Interfaces>"
    "<NetworkInterface address='127.0.0.1'/></Interfaces><AllowMulticast>false</AllowMulticast>"
    "</General><Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30"
    "</MaxAutoParticipantIndex><Peers><Peer address='127.0.0.1'/></Peers></Discovery></Domain>"
    "</CycloneDDS>"
)

from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


# The ROS 2 interface definitions, written out independently of spomp's (DDS type names as
# rmw implementations register them).
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header
    pose: Pose


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


ROWS, COLS, VFOV = 64, 512, math.pi / 2
SENSOR_HEIGHT = 0.4
SCALE = 1.0 / 512.0


def flat_ground_panorama(stamp):
    """Open flat ground: rows below the horizon see the ground at h / sin(-elevation), rows
    above it see nothing; labels: 1 (the default table's road) where there is ground."""
    depth = bytearray()
    labels = bytearray()
    for r in range(ROWS):
        elev = VFOV / 2 - r * VFOV / (ROWS - 1)
        rng = SENSOR_HEIGHT / math.sin(-elev) if elev < -0.02 else 0.0
        count = 0 if rng <= 0 or rng > 60 else min(65535, round(rng / SCALE))
        label = 1 if count else 0
        for _ in range(COLS):
            depth += count.to_bytes(2, "little")
            labels.append(label)
    hdr = Header(stamp=stamp, frame_id="ugv1/lidar")
    d = Image(header=hdr, height=ROWS, width=COLS, encoding="mono16", is_bigendian=0, step=COLS * 2, data=list(depth))
    s = Image(header=hdr, height=ROWS, width=COLS, encoding="mono8", is_bigendian=0, step=COLS, data=list(labels))
    return d, s


def main():
    spomp = sys.argv[1] if len(sys.argv) > 1 else "target/debug/spomp"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_DOMAIN_ID", None)
    proc = subprocess.Popen(
        [spomp, "run", "tests/missions/ros2/interop.yaml", "--robot", "ugv1", "--json",
         "--domain-id", str(DOMAIN), "--until-s", "25"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)

    dp = DomainParticipant(DOMAIN)
    reliable = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)), Policy.History.KeepLast(5))
    best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
    odom_w = DataWriter(dp, Topic(dp, "rt/ugv1/odom", Odometry), qos=reliable)
    depth_w = DataWriter(dp, Topic(dp, "rt/ugv1/panorama/depth", Image), qos=reliable)
    sem_w = DataWriter(dp, Topic(dp, "rt/ugv1/panorama/semantic", Image), qos=reliable)
    pose_w = DataWriter(dp, Topic(dp, "rt/ugv1/pose_in", PoseStamped), qos=reliable)
    cmd_r = DataReader(dp, Topic(dp, "rt/ugv1/cmd_vel", Twist), qos=best_effort)

    start = time.time()
    x = 0.0
    commands = []
    next_pano = 0.0
    while time.time() - start < 22 and proc.poll() is None:
        now = time.time()
        stamp = Time(sec=int(now), nanosec=int((now % 1) * 1e9))
        q = Quaternion(0.0, 0.0, 0.0, 1.0)
        odom = Odometry(
            header=Header(stamp=stamp, frame_id="ugv1/odom"), child_frame_id="ugv1/base_link",
            pose=PoseWithCovariance(pose=Pose(Point(x, 0.0, 0.0), q), covariance=[0.0] * 36),
            twist=TwistWithCovariance(twist=Twist(Vector3(0.0, 0.0, 0.0), Vector3(0.0, 0.0, 0.0)),
                                      covariance=[0.0] * 36))
        odom_w.write(odom)
        pose_w.write(PoseStamped(header=Header(stamp=stamp, frame_id="map"),
                                 pose=Pose(Point(12.0 + x, 5.0, 0.0), q)))
        if now - start >= next_pano:
            next_pano += 1.0
            d, s = flat_ground_panorama(stamp)
            depth_w.write(d)
            sem_w.write(s)
        for c in cmd_r.take(N=50):
            commands.append((c.linear.x, c.angular.z))
        # The robot drives straight ahead at the commanded speed.
        if commands:
            x += max(0.0, commands[-1][0]) * 0.05
        time.sleep(0.05)

    out, err = proc.communicate(timeout=60)
    if proc.returncode != 0:
        print(f"spomp run failed ({proc.returncode}):\n{err}", file=sys.stderr)
        return 1
    report = json.loads(out)
    received = report["received"]
    problems = []
    if received["odometry"] < 50:
        problems.append(f"spomp decoded {received['odometry']} odometry messages from Cyclone DDS")
    if received["panoramas"] < 5:
        problems.append(f"spomp paired {received['panoramas']} panoramas from Cyclone DDS")
    if received["poses"] < 50:
        problems.append(f"spomp decoded {received['poses']} poses from Cyclone DDS")
    if report["malformed_inputs"] != 0:
        problems.append(f"spomp refused {report['malformed_inputs']} inputs")
    if len(commands) < 20:
        problems.append(f"Cyclone DDS decoded {len(commands)} velocity commands from spomp")
    forward = [v for v, _ in commands if v > 0.05]
    if not forward:
        problems.append(f"spomp never commanded the robot forward toward its goal: {commands[-10:]}")
    if problems:
        print("\n".join(problems), file=sys.stderr)
        print(err, file=sys.stderr)
        return 1
    print(f"cyclonedds interop: {received['odometry']} odometry, {received['panoramas']} panoramas, "
          f"{received['poses']} poses into spomp; {len(commands)} commands out "
          f"({len(forward)} forward, up to {max(forward):.2f} m/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
