#!/usr/bin/env python3
"""Checks the layering rules of docs/design.md §2 on the workspace's dependency graph.

Layers, bottom to top: core < messages < skills < behaviors (engine + mission language) < robot
< world < adapters < the CLI (root package).
- core depends on no spomp crate;
- messages (`core/ros_msgs`: the ROS 2 message types as plain data) depend on core only;
- a skill depends only on core and other skills (never behaviours, the robot or adapters);
- behaviours (the engine and the mission language) depend on core only: they know no message
  type, skill, robot or adapter (an adapter's mission section is an opaque value to the
  language, typed and checked by its owner, registered beside the node types);
- the robot (runtime, domain nodes, mission → robot) depends on core, messages, skills and
  behaviours;
- the world model (`world/`: layers, world files, the city generator, a mission's world and
  operating area) is data that may be read from files: it depends on core, skills, behaviours
  and the robot, and adapters and the CLI use it (never the robot);
- an adapter depends on core, messages, skills, behaviours, the robot and the world, never on
  another adapter;
- only the root `spomp` package wires adapters together;
- tools (benchmark support) depend on no spomp crate and are used as dev-dependencies only.
Dev-dependencies (tests, benchmarks, examples) obey the same rules: a skill's tests cannot
reach up to the robot, nor an adapter's tests into another adapter; tools are the one extra a
dev-dependency may name, besides the package itself (to turn its own features on for its tests).
Every spomp crate must live in a known layer directory.

Inside `spomp-behaviors`, the engine (every module but `mission/`) knows nothing of the mission
language: no engine source file names `crate::mission` / `spomp_behaviors::mission` (the
language builds engine trees, never the other way round). Comments are not checked.
Exit 1 on any violation.
"""
import json
import os
import re
import subprocess
import sys


def layer_of(manifest_dir: str, root: str) -> str:
    rel = os.path.relpath(manifest_dir, root)
    if rel == ".":
        return "cli"
    if rel == "core":
        return "core"
    if rel == os.path.join("core", "ros_msgs"):
        return "messages"
    if rel == "world":
        return "world"
    if rel == "behaviors":
        return "behaviors"
    if rel == "robot":
        return "robot"
    if rel == "examples" or rel.startswith("examples" + os.sep):
        return "example"
    if rel.startswith("skills" + os.sep):
        return "skill"
    if rel.startswith("adapters" + os.sep):
        return "adapter"
    if rel == "tests" or rel.startswith("tests" + os.sep):
        return "tests"
    if rel.startswith("tools" + os.sep):
        return "tool"
    return "unknown:" + rel


ALLOWED = {
    "tool": set(),
    "core": set(),
    "skill": {"core", "skill"},
    "messages": {"core"},
    "behaviors": {"core"},
    "robot": {"core", "messages", "skill", "behaviors"},
    "world": {"core", "skill", "behaviors", "robot"},
    "adapter": {"core", "messages", "skill", "behaviors", "robot", "world"},
    "cli": {"core", "messages", "skill", "behaviors", "robot", "world", "adapter"},
    "example": {"core", "messages", "skill", "behaviors", "robot", "world", "adapter", "cli"},
    "tests": {"core", "messages", "skill", "behaviors", "robot", "world", "adapter", "cli"},
}


# A path into the mission language from inside the crate or from outside it.
LANGUAGE_PATH = re.compile(r"\b(crate|super|spomp_behaviors)\s*::\s*(\{[^}]*\bmission\b|mission\b)")


def engine_language_problems(root: str) -> list:
    """Engine modules of `spomp-behaviors` that reach into its mission language."""
    src = os.path.join(root, "behaviors", "src")
    language = os.path.join(src, "mission")
    problems = []
    for folder, _dirs, files in os.walk(src):
        if folder == language or folder.startswith(language + os.sep):
            continue
        for f in sorted(files):
            if not f.endswith(".rs"):
                continue
            path = os.path.join(folder, f)
            with open(path, encoding="utf-8") as fh:
                for n, line in enumerate(fh, 1):
                    code = line.split("//", 1)[0]
                    if LANGUAGE_PATH.search(code):
                        rel = os.path.relpath(path, root)
                        problems.append(
                            f"{rel}:{n}: the engine must not use the mission language ({code.strip()})"
                        )
    return problems


def main() -> int:
    meta = json.loads(
        subprocess.check_output(["cargo", "metadata", "--no-deps", "--format-version", "1"])
    )
    root = meta["workspace_root"]
    ours = {}
    for pkg in meta["packages"]:
        ours[pkg["name"]] = layer_of(os.path.dirname(pkg["manifest_path"]), root)
    problems = []
    for pkg in meta["packages"]:
        name = pkg["name"]
        layer = ours[name]
        if layer.startswith("unknown:"):
            problems.append(f"{name}: lives in {layer[8:]}, which is no layer directory")
            continue
        for dep in pkg["dependencies"]:
            if dep["name"] not in ours:
                continue
            dep_layer = ours[dep["name"]]
            is_dev = dep.get("kind") == "dev"
            if is_dev and dep["name"] == name:
                # A package naming itself as a dev-dependency turns on its own features for its
                # tests (the CLI's `deploy`): no edge between crates.
                continue
            if dep_layer == "tool":
                if not is_dev and layer != "tool":
                    problems.append(f"{name} ({layer}) may use the tool {dep['name']} as a dev-dependency only")
                continue
            if dep_layer not in ALLOWED[layer]:
                what = "have a dev-dependency on" if is_dev else "depend on"
                problems.append(f"{name} ({layer}) must not {what} {dep['name']} ({dep_layer})")
    problems.extend(engine_language_problems(root))
    for p in problems:
        print("layering:", p)
    if problems:
        return 1
    print(
        f"layering: {len(ours)} crates, all dependencies (dev-dependencies too) respect the layers; "
        "the engine of spomp-behaviors uses no mission language"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
