#!/usr/bin/env python3
"""Runs a mission as robots run it, paced in real time: `spomp sim --ros2 --rate R` as the robot
farm and one `spomp run --use-sim-time` process per robot (basestation included), the team state
over the signed Zenoh link, everything on loopback. Prints one JSON line per seed with the farm's
summary figures (clusters visited, UAV distance) and the robots' exit codes.

Unlike `spomp experiment --deployed` (lockstep: the farm waits for every robot each step, so the
machine's load cannot change a run), a paced run keeps going while a robot is late, as on real
robots; on one machine the processes share its cores, so its figures depend on the load.

    python3 scripts/paced-farm.py missions/visit-all-vehicle-clusters.yaml --seeds 1-3 --rate 2

Use a release build (`cargo build --release`); `--spomp` names another binary.
"""

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time


def free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_domain():
    """A DDS domain id whose first participant's discovery port (7400 + 250 × id + 10) nobody on
    the machine holds."""
    for domain in range(101 + os.getpid() % 100, 233):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", 7410 + 250 * domain))
            except OSError:
                continue
        return domain
    sys.exit("no free DDS domain id")


def team_of(keys):
    """The robots of the team, from the key folder `spomp keys generate` wrote."""
    with open(os.path.join(keys, "team.json")) as f:
        return sorted(json.load(f)["members"])


def seeds_of(text):
    if "-" in text:
        a, b = text.split("-", 1)
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def run_seed(args, seed, work):
    keys = os.path.join(work, f"keys-{seed}")
    subprocess.run([args.spomp, "keys", "generate", args.mission, "--out", keys], check=True,
                   stdout=subprocess.DEVNULL)
    robots = args.robots.split(",") if args.robots else team_of(keys)
    domain = free_domain()
    ports = [free_port() for _ in robots]
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_DOMAIN_ID", None)
    common = ["--domain-id", str(domain), "--interface", "127.0.0.1"]
    farm_out = os.path.join(work, f"farm-{seed}.json")
    farm_cmd = [args.spomp, "sim", args.mission, "--ros2", "--rate", str(args.rate), "--seed", str(seed),
                "--json", "--no-mcap", "--out", os.path.join(work, f"sim-{seed}")] + common
    if args.time_limit_s:
        farm_cmd += ["--time-limit-s", str(args.time_limit_s)]
    children = []
    try:
        with open(farm_out, "w") as out, open(os.path.join(work, f"farm-{seed}.log"), "w") as err:
            farm = subprocess.Popen(farm_cmd, stdout=out, stderr=err, env=env, stdin=subprocess.DEVNULL)
        for i, robot in enumerate(robots):
            cmd = [args.spomp, "run", args.mission, "--robot", robot, "--use-sim-time", "--seed", str(seed),
                   "--keys", keys, "--listen", f"tcp/127.0.0.1:{ports[i]}", "--json"] + common
            for p in ports[:i]:
                cmd += ["--connect", f"tcp/127.0.0.1:{p}"]
            with open(os.path.join(work, f"{robot}-{seed}.json"), "w") as out, \
                    open(os.path.join(work, f"{robot}-{seed}.log"), "w") as err:
                children.append((robot, subprocess.Popen(cmd, stdout=out, stderr=err, env=env,
                                                         stdin=subprocess.DEVNULL)))
        farm_rc = farm.wait()
    finally:
        for _, child in children:
            if child.poll() is None:
                child.send_signal(signal.SIGINT)
        deadline = time.time() + 20
        for _, child in children:
            try:
                child.wait(timeout=max(0.1, deadline - time.time()))
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
    with open(farm_out) as f:
        text = f.read()
    try:
        summary = json.loads(text)
    except json.JSONDecodeError:
        summary = {}
    row = {"seed": seed, "rate": args.rate, "farm_exit": farm_rc,
           "robot_exits": {r: c.returncode for r, c in children}}
    run = (summary.get("runs") or [{}])[0]
    row["outcome"] = run.get("outcome")
    row["end_s"] = run.get("end_s")
    row["clusters"] = run.get("clusters")
    row["uav_distance_m"] = sum(r.get("distance_m", 0.0) for r in run.get("robots", []) if r.get("kind") == "uav")
    row["problems"] = len(run.get("problems", []))
    row["summary_file"] = farm_out
    return row


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mission")
    p.add_argument("--seeds", default="1", help="e.g. 1-3 or 1,4,7")
    p.add_argument("--rate", type=float, default=1.0, help="simulated seconds per wall second")
    p.add_argument("--time-limit-s", type=float, default=None)
    p.add_argument("--robots", default=None, help="comma-separated robot ids (default: the mission's team)")
    p.add_argument("--spomp", default=os.path.join(os.path.dirname(__file__), "..", "target", "release", "spomp"))
    p.add_argument("--out", default=None, help="folder for the processes' output (default: a temporary one)")
    args = p.parse_args()
    if not shutil.which(args.spomp) and not os.path.exists(args.spomp):
        sys.exit(f"{args.spomp}: not found (cargo build --release)")
    work = args.out or tempfile.mkdtemp(prefix="spomp-paced-")
    os.makedirs(work, exist_ok=True)
    for seed in seeds_of(args.seeds):
        print(json.dumps(run_seed(args, seed, work)), flush=True)


if __name__ == "__main__":
    main()
