#!/usr/bin/env python3
"""Checks that the README's two commands share their dependencies' builds.

The first command (`cargo run --release`) builds the `spomp` package with its default features;
the second (`cargo test --workspace --release`) builds the whole workspace with the `deploy`
feature and the dev-dependencies. A crate both builds use must be resolved with the same features
in both, or the second command compiles it again, and every crate above it (a proc macro's `syn`
with one more feature rebuilds everything that derives). The `spomp` package pins such features
in its `Cargo.toml` ("feature pins"); this script fails when a shared crate's features differ and
names the crate and the features to pin. Our own crates are left out: the adapters and the CLI
are meant to differ between the two builds.

Exit 0 when every shared crate matches, 1 otherwise.
"""
import subprocess
import sys


def host_triple() -> str:
    for line in subprocess.check_output(["rustc", "-vV"], text=True).splitlines():
        if line.startswith("host: "):
            return line[len("host: "):]
    raise SystemExit("feature pins: rustc -vV names no host")


def resolved(args: list, target: str) -> dict:
    """package id -> the set of feature lists it is built with, per `cargo tree`.

    With `--target`, `cargo tree` lists a crate built for the host (under a proc macro or build
    script) apart from the same crate built for the target, as the build resolves them."""
    out = subprocess.check_output(
        ["cargo", "tree", "--locked", "--prefix", "none", "--format", "{p}|{f}", "--target", target, *args],
        text=True,
    )
    seen = {}
    for line in out.splitlines():
        line = line.removesuffix(" (*)").strip()
        if "|" not in line:
            continue
        package, features = line.rsplit("|", 1)
        if "(/" in package:  # a path dependency: one of ours
            continue
        seen.setdefault(package, set()).add(features)
    return seen


def main() -> int:
    target = host_triple()
    first = resolved(["-p", "spomp", "-e", "normal,build"], target)
    second = resolved(["--workspace", "-e", "normal,build,dev"], target)
    problems = []
    for package, variants in sorted(first.items()):
        for features in sorted(variants):
            if features not in second.get(package, set()):
                others = " or ".join(f"[{f}]" for f in sorted(second.get(package, set()))) or "nothing"
                problems.append(f"{package}: [{features}] in the first command's build, {others} in the test build")
    for p in problems:
        print("feature pins:", p)
    if problems:
        print("feature pins: pin the test build's features in the root Cargo.toml (see its feature pins)")
        return 1
    print(f"feature pins: the {len(first)} crates of the README's first build are resolved as the test build resolves them")
    return 0


if __name__ == "__main__":
    sys.exit(main())
