#!/usr/bin/env python3
"""Checks that the README's second command rebuilds nothing of what its first command built.

The first command (`cargo run --release`) builds the `spomp` package with its default features;
the second (`cargo test --workspace --release`) builds the whole workspace with the `deploy`
feature and the dev-dependencies. A crate both builds use must come out as the same compilation
unit in both — same features, profile and dependencies, all the way down — or the second command
compiles it again, and every crate above it (`libc` with one more feature rebuilds nearly the
whole build). The `spomp` package pins such features in its `Cargo.toml` ("feature pins").

This compares cargo's unit graphs of the two commands (`--unit-graph`, a nightly flag that
RUSTC_BOOTSTRAP=1 unlocks on a stable toolchain; nothing is compiled). Only the units meant to
differ may: the `spomp` package and the two adapters whose network stacks are the `deploy`
feature. Exit 0 when nothing else differs; 1 with the units whose own features differ (what to
pin) and how many units their difference rebuilds.
"""
import hashlib
import json
import os
import subprocess
import sys

# Built with other features by design: the CLI with `deploy`, and the adapters it turns on.
MEANT_TO_DIFFER = {"spomp", "spomp-ros2", "spomp-zenoh"}


def unit_graph(args: list) -> list:
    env = dict(os.environ, RUSTC_BOOTSTRAP="1")
    out = subprocess.check_output(
        ["cargo", *args, "--release", "--locked", "--unit-graph", "-Z", "unstable-options"], env=env, text=True
    )
    return json.loads(out)["units"]


def package(unit: dict) -> str:
    """`name@version` from a package id (registry or path)."""
    return unit["pkg_id"].rsplit("#", 1)[-1].rsplit("/", 1)[-1]


def identities(units: list) -> dict:
    """unit index -> a digest of everything that makes the unit's build: package, target, mode,
    features, profile and the identities of its dependencies."""
    memo = {}

    def ident(i: int) -> str:
        if i not in memo:
            u = units[i]
            deps = sorted(ident(d["index"]) + d["extern_crate_name"] for d in u["dependencies"])
            text = json.dumps(
                [u["pkg_id"], u["target"]["name"], u["mode"], u["features"], u["profile"], u.get("platform"), deps],
                sort_keys=True,
            )
            memo[i] = hashlib.sha256(text.encode()).hexdigest()
        return memo[i]

    return {i: ident(i) for i in range(len(units))}


def main() -> int:
    first = unit_graph(["build"])
    second = unit_graph(["test", "--workspace", "--no-run"])
    second_ids = set(identities(second).values())
    # The same unit's features in the second build, for the message (host and target units apart).
    def slot(u: dict) -> tuple:
        return (u["pkg_id"], u["target"]["name"], u["mode"], u["profile"]["opt_level"])

    second_features = {}
    for u in second:
        second_features.setdefault(slot(u), []).append(u["features"])
    rebuilt, causes = [], []
    for i, ident in identities(first).items():
        u = first[i]
        name = package(u).split("@")[0]
        if ident in second_ids or name in MEANT_TO_DIFFER:
            continue
        rebuilt.append(u)
        others = second_features.get(slot(u), [])
        if u["features"] not in others:
            causes.append(f"{package(u)} ({u['target']['name']}, {u['mode']}): {u['features']} here, "
                          f"{' or '.join(map(str, others)) or 'absent'} in the test build")
    if not rebuilt:
        print(f"feature pins: the test build reuses all {len(first)} units of the README's first build "
              f"but the {len(MEANT_TO_DIFFER)} packages built with other features by design")
        return 0
    for c in causes:
        print("feature pins:", c)
    print(f"feature pins: {len(rebuilt)} units of the first build would be compiled again by the test build; "
          "pin the test build's features in the root Cargo.toml (its feature pins)")
    return 1


if __name__ == "__main__":
    sys.exit(main())
