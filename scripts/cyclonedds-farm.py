#!/usr/bin/env python3
"""A viewer written with Eclipse Cyclone DDS (PyPI `cyclonedds`) watches a simulator farm:
`spomp sim --ros2` simulates a UGV's body and sensors, `spomp run` drives it, and this script
reads what rviz, tf2 and robot_localization would, decoded by Cyclone from its own definitions
of the ROS 2 types:

- `/tf` and `/tf_static` (the latter as tf2's static listener reads it: reliable, transient
  local): every frame a message names — the odometry's, the depth image's — must reach `map`
  through one parent each (`ugv1/lidar → ugv1/base_link → ugv1/odom → map`);
- `/ugv1/panorama/depth`: REP-118's canonical `32FC1`, metres, +inf where nothing returned;
- `/ugv1/odom`: covariances from the simulator's noise model — x, y and yaw variances above
  zero that grow as the robot drives, correlations where the model has them, the unmeasured
  axes (z, roll, pitch) at a large variance.

Everything it checks is a property of the messages, not of timing: it reads until the farm's
run ends. Loopback only: Cyclone bound to 127.0.0.1 without multicast, spomp with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, on a domain of this run's own.

    python3 scripts/cyclonedds-farm.py target/debug/spomp
"""

import json
import math
import os
import signal
import struct
import subprocess
import sys
import tempfile
import time

DOMAIN = 100 + os.getpid() % 50

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

# The ROS 2 types, defined independently of spomp's (shared with the driver interop script).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cyclonedds_types import Image, Odometry, TFMessage  # noqa: E402

MISSION = "tests/missions/ros2/farm-one-ugv.yaml"
UNMEASURED = 1e6


def main():
    spomp = sys.argv[1] if len(sys.argv) > 1 else "target/debug/spomp"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_DOMAIN_ID", None)
    out = tempfile.mkdtemp(prefix="spomp-farm-interop-")
    d = str(DOMAIN)
    sim = subprocess.Popen(
        [spomp, "sim", MISSION, "--ros2", "--domain-id", d, "--drive", "ugv1", "--rate", "4", "--no-mcap",
         "--time-limit-s", "40", "--json", "--out", out],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    run = subprocess.Popen(
        [spomp, "run", MISSION, "--robot", "ugv1", "--use-sim-time", "--json", "--domain-id", d],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)

    dp = DomainParticipant(DOMAIN)
    best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(50))
    latched = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
                  Policy.Durability.TransientLocal, Policy.History.KeepLast(1))
    tf_r = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=best_effort)
    static_r = DataReader(dp, Topic(dp, "rt/tf_static", TFMessage), qos=latched)
    odom_r = DataReader(dp, Topic(dp, "rt/ugv1/odom", Odometry), qos=best_effort)
    depth_r = DataReader(dp, Topic(dp, "rt/ugv1/panorama/depth", Image), qos=best_effort)

    parents = {}  # child -> set of parents
    named = set()
    odoms = []
    depths = []
    start = time.time()
    while sim.poll() is None and time.time() - start < 240:
        for r in (tf_r, static_r):
            for m in r.take(N=100):
                if isinstance(m, TFMessage):
                    for t in m.transforms:
                        parents.setdefault(t.child_frame_id, set()).add(t.header.frame_id)
        for m in odom_r.take(N=100):
            if isinstance(m, Odometry):
                odoms.append(m)
                named.update([m.header.frame_id, m.child_frame_id])
        for m in depth_r.take(N=10):
            if isinstance(m, Image):
                depths.append(m)
                named.add(m.header.frame_id)
        time.sleep(0.02)
    sim_out, sim_err = sim.communicate(timeout=120)
    run.send_signal(signal.SIGINT)
    try:
        run_out, run_err = run.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        run.kill()
        run_out, run_err = run.communicate()

    problems = []
    # The mission's outcome in a paced farm depends on the machine's speed: not checked here
    # (tests/ros2_farm.rs checks outcomes in lockstep), only that the farm ran.
    if sim.returncode not in (0, 1) or not json.loads(sim_out or "{}").get("runs"):
        problems.append(f"spomp sim failed ({sim.returncode}): {sim_err[-2000:]}")

    # tf: every frame a message names reaches map, each child with one parent.
    for child, ps in parents.items():
        if len(ps) != 1:
            problems.append(f"tf: {child} has parents {sorted(ps)}")
    if not named:
        problems.append("no odometry or depth image named a frame")
    for frame in sorted(named):
        at, hops = frame, 0
        while at != "map" and hops < 10:
            at = next(iter(parents.get(at, {"<none>"})))
            hops += 1
        if at != "map":
            problems.append(f"tf: {frame} does not reach map (stops at {at}; tree {parents})")

    # Depth: REP-118's canonical encoding.
    if not depths:
        problems.append("no depth image from the farm")
    for img in depths[:3]:
        if (img.encoding, img.step, img.is_bigendian) != ("32FC1", img.width * 4, 0):
            problems.append(f"depth image {img.encoding}, step {img.step} for width {img.width}")
            continue
        ranges = struct.unpack(f"<{img.width * img.height}f", bytes(img.data))
        ground = [r for r in ranges if math.isfinite(r)]
        if not ground or min(ground) <= 0.0 or not any(0.3 < r < 60.0 for r in ground):
            problems.append(f"depth: no plausible ground ranges (min {min(ground, default=None)})")
        if not any(r == math.inf for r in ranges):
            problems.append("depth: no +inf (no return) above the horizon")
        if any(math.isnan(r) or r == 0.0 for r in ranges):
            problems.append("depth: zeros or NaN where REP-117 wants +inf")

    # Odometry covariance from the noise model.
    moved = [o for o in odoms if math.hypot(o.pose.pose.position.x, o.pose.pose.position.y) > 2.0]
    if not odoms or not moved:
        problems.append(f"{len(odoms)} odometry messages, {len(moved)} after 2 m of driving")
    else:
        first, last = odoms[0].pose.covariance, moved[-1].pose.covariance
        diag = [last[0], last[7], last[35]]
        if min(diag) <= 0.0:
            problems.append(f"odometry pose variances (x, y, yaw) {diag}")
        if not last[0] + last[7] > first[0] + first[7]:
            problems.append(f"odometry position variance does not grow: {first[0] + first[7]} -> {last[0] + last[7]}")
        if any(last[k * 7] != UNMEASURED for k in (2, 3, 4)):
            problems.append(f"z, roll, pitch variances {[last[k * 7] for k in (2, 3, 4)]}, expected {UNMEASURED}")
        if last[5] == 0.0 and last[11] == 0.0:
            problems.append("odometry x-yaw and y-yaw covariances are zero after turning and driving")
        twist = moved[-1].twist.covariance
        if twist[0] <= 0.0 or twist[35] <= 0.0:
            problems.append(f"odometry twist variances {twist[0]}, {twist[35]}")

    if run.returncode not in (0, 130, -2):
        problems.append(f"spomp run exited {run.returncode}: {run_err[-2000:]}")
    if problems:
        print("\n".join(problems), file=sys.stderr)
        return 1
    last = moved[-1].pose.covariance
    print(f"cyclonedds farm interop: tf {sorted(named)} all reach map; {len(depths)} depth images 32FC1 "
          f"{depths[0].height}x{depths[0].width}; {len(odoms)} odometry, after "
          f"{math.hypot(moved[-1].pose.pose.position.x, moved[-1].pose.pose.position.y):.1f} m "
          f"sigma x {math.sqrt(last[0]):.3f} m, y {math.sqrt(last[7]):.3f} m, yaw {math.sqrt(last[35]):.4f} rad")
    return 0


if __name__ == "__main__":
    sys.exit(main())
