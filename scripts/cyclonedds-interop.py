#!/usr/bin/env python3
"""Interop with a DDS implementation that is not ours: Eclipse Cyclone DDS (PyPI `cyclonedds`)
plays the robot's drivers for `spomp run`.

It publishes odometry, a panorama (depth in REP-118's `32FC1` metres, and labels) and a
ground-truth pose in the standard ROS 2 types, encoded by Cyclone from its own definitions of
them, and subscribes to spomp's velocity
commands (`geometry_msgs/TwistStamped`, the default `ros2.cmd_vel_type`, as Jazzy's
diff_drive_controller takes them), to `/tf` and, with rcl's `/rosout` profile (reliable,
transient local, depth 1000), to `/rosout`. It passes when spomp decodes every input (its report
counts them, none malformed), commands the robot forward toward its goal in its body frame,
publishes `map → ugv1/odom`, and every node transition reaches the transient-local `/rosout`
reader — which joins late, after spomp started, as a late joiner does. The labels arrive in a
frame other than the configured sensor frame: spomp must say so (`frame_mismatches`).

It also plays rviz's "Publish Point" tool: with the team's keys and `--clicked-point`, spomp
takes a `geometry_msgs/PointStamped` on `/clicked_point` in the map frame as the operator's
"add goal" and refuses one in another frame, and says so on `/rosout`.

Loopback only: Cyclone is bound to 127.0.0.1 without multicast, spomp runs with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, on a domain of this test's own.

    python3 scripts/cyclonedds-interop.py target/debug/spomp
"""

import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import time

DOMAIN = 150 + os.getpid() % 50

from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

# The ROS 2 types, written out independently of spomp's.
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cyclonedds_types import (  # noqa: E402
    Header, Image, Log, Odometry, Point, PointStamped, Pose, PoseStamped, PoseWithCovariance, Quaternion, TFMessage, Time,
    Twist, TwistStamped, TwistWithCovariance, Vector3)


ROWS, COLS, VFOV = 64, 512, math.pi / 2
SENSOR_HEIGHT = 0.4


def flat_ground_panorama(stamp):
    """Open flat ground: rows below the horizon see the ground at h / sin(-elevation) metres, rows
    above it see nothing (+inf); labels: 1 (the default table's road) where there is ground."""
    depth = bytearray()
    labels = bytearray()
    for r in range(ROWS):
        elev = VFOV / 2 - r * VFOV / (ROWS - 1)
        rng = SENSOR_HEIGHT / math.sin(-elev) if elev < -0.02 else math.inf
        rng = rng if rng <= 60 else math.inf
        label = 1 if math.isfinite(rng) else 0
        for _ in range(COLS):
            depth += struct.pack("<f", rng)
            labels.append(label)
    hdr = Header(stamp=stamp, frame_id="ugv1/lidar")
    # REP-118's canonical depth: 32FC1 metres, +inf where nothing returns (REP-117).
    d = Image(header=hdr, height=ROWS, width=COLS, encoding="32FC1", is_bigendian=0, step=COLS * 4, data=list(depth))
    # A frame the mission does not configure: spomp uses the labels and reports the mismatch.
    wrong = Header(stamp=stamp, frame_id="camera")
    s = Image(header=wrong, height=ROWS, width=COLS, encoding="mono8", is_bigendian=0, step=COLS, data=list(labels))
    return d, s


def main():
    spomp = sys.argv[1] if len(sys.argv) > 1 else "target/debug/spomp"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_DOMAIN_ID", None)
    scratch = tempfile.TemporaryDirectory(prefix="spomp-interop-")  # removed at exit
    keys = os.path.join(scratch.name, "keys")
    subprocess.run([spomp, "keys", "generate", "tests/missions/ros2/interop.yaml", "--out", keys],
                   check=True, capture_output=True)
    proc = subprocess.Popen(
        [spomp, "run", "tests/missions/ros2/interop.yaml", "--robot", "ugv1", "--json",
         "--domain-id", str(DOMAIN), "--until-s", "25", "--keys", keys, "--clicked-point"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)

    dp = DomainParticipant(DOMAIN)
    reliable = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)), Policy.History.KeepLast(5))
    best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
    odom_w = DataWriter(dp, Topic(dp, "rt/ugv1/odom", Odometry), qos=reliable)
    depth_w = DataWriter(dp, Topic(dp, "rt/ugv1/panorama/depth", Image), qos=reliable)
    sem_w = DataWriter(dp, Topic(dp, "rt/ugv1/panorama/semantic", Image), qos=reliable)
    pose_w = DataWriter(dp, Topic(dp, "rt/ugv1/pose_in", PoseStamped), qos=reliable)
    cmd_r = DataReader(dp, Topic(dp, "rt/ugv1/cmd_vel", TwistStamped), qos=best_effort)
    tf_r = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=best_effort)
    # rviz's "Publish Point": reliable, on the global /clicked_point.
    click_w = DataWriter(dp, Topic(dp, "rt/clicked_point", PointStamped), qos=reliable)
    clicked = False
    # rcl's /rosout profile; created after spomp started, so it joins late.
    rosout_qos = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
                     Policy.Durability.TransientLocal, Policy.History.KeepLast(1000))
    rosout_topic = Topic(dp, "rt/rosout", Log)
    rosout_r = None
    logs = []
    tf_pairs = set()
    cmd_frames = set()

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
        if not clicked and now - start > 5.0:
            # Ahead of the robot on its way (a goal it may take without turning back), then
            # one in a frame spomp does not take.
            click_w.write(PointStamped(header=Header(stamp=stamp, frame_id="map"), point=Point(60.0, 5.0, 0.0)))
            click_w.write(PointStamped(header=Header(stamp=stamp, frame_id="ugv1/odom"), point=Point(1.0, 1.0, 0.0)))
            clicked = True
        if rosout_r is None and now - start > 3.0:
            rosout_r = DataReader(dp, rosout_topic, qos=rosout_qos)
        if rosout_r is not None:
            logs.extend(e for e in rosout_r.take(N=1000) if isinstance(e, Log))
        for t in tf_r.take(N=50):
            if not isinstance(t, TFMessage):
                continue
            for ts in t.transforms:
                tf_pairs.add((ts.header.frame_id, ts.child_frame_id))
        for c in cmd_r.take(N=50):
            if not isinstance(c, TwistStamped):
                continue
            commands.append((c.twist.linear.x, c.twist.angular.z))
            cmd_frames.add(c.header.frame_id)
        # The robot drives straight ahead at the commanded speed.
        if commands:
            x += max(0.0, commands[-1][0]) * 0.05
        time.sleep(0.05)

    out, err = proc.communicate(timeout=60)
    if rosout_r is not None:
        logs.extend(e for e in rosout_r.take(N=1000) if isinstance(e, Log))
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
    if cmd_frames != {"ugv1/base_link"}:
        problems.append(f"velocity commands stamped in frames {cmd_frames}, expected ugv1/base_link")
    if ("map", "ugv1/odom") not in tf_pairs:
        problems.append(f"no map -> ugv1/odom on /tf: {tf_pairs}")
    transitions = [entry for entry in logs if " -> " in entry.msg]
    if not transitions:
        problems.append(f"the late transient-local /rosout reader got no node transition ({len(logs)} entries)")
    else:
        ticks = [int(e.msg.split("(tick ")[1].split(",")[0]) for e in transitions if "(tick " in e.msg]
        if not ticks or min(ticks) > 1:
            problems.append(f"the late /rosout reader missed the first tick's transitions: first {transitions[0].msg}")
    if any(entry.name != "ugv1.spomp" for entry in logs):
        problems.append(f"rosout logger names: {sorted({entry.name for entry in logs})}")
    mismatches = report.get("frame_mismatches", {})
    if mismatches.get("/ugv1/panorama/semantic header.frame_id") != "camera":
        problems.append(f"spomp did not report the labels' frame `camera`: {mismatches}")
    if received.get("operator_points") != 2 or report.get("operator_points_refused") != 1:
        problems.append(f"clicked points: {received.get('operator_points')} taken, "
                        f"{report.get('operator_points_refused')} refused; expected 2 and 1")
    if not any(e.msg.startswith("clicked point: goal operator/") for e in logs):
        problems.append("no /rosout entry of the clicked point's goal")
    if not any(e.msg.startswith("clicked point refused: a point in frame `ugv1/odom`") for e in logs):
        problems.append("no /rosout entry of the refused clicked point")
    if not forward:
        problems.append(f"spomp never commanded the robot forward toward its goal: {commands[-10:]}")
    if problems:
        print("\n".join(problems), file=sys.stderr)
        print(err, file=sys.stderr)
        return 1
    print(f"cyclonedds interop: {received['odometry']} odometry, {received['panoramas']} panoramas, "
          f"{received['poses']} poses into spomp; {len(commands)} commands out "
          f"({len(forward)} forward, up to {max(forward):.2f} m/s, TwistStamped in ugv1/base_link); "
          f"/tf map -> ugv1/odom; {len(transitions)} transitions on /rosout to a late transient-local reader; "
          f"frame mismatch reported; a clicked point became the operator's goal, one in another frame refused")
    return 0


if __name__ == "__main__":
    sys.exit(main())
