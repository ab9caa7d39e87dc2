#!/usr/bin/env python3
"""The dependency rule of ARCHITECTURE.md, checked on the workspace.

1. Each workspace crate depends (normal, build and dev dependencies) only on
   workspace crates of a lower layer: no import circles, not even through
   dev-dependencies.
2. The pure crates (dexitac-tactile, dexitac-gripper) depend on nothing in
   the project but dexitac-protocol, and nothing they build with, tests
   included, pulls in a window, recording, serial, camera, JPEG or
   command-line crate (`cargo tree`, transitive).

Exit 0 when the rule holds, 1 with the offending edges otherwise.
"""
import json
import subprocess
import sys

LAYERS = {
    "dexitac-protocol": 0,
    "dexitac-firmware": 1,
    "dexitac-tactile": 1,
    "dexitac-gripper": 1,
    "dexitac-rig": 2,
    "dexitac-sim": 3,
    "dexitac-view": 4,
    "dexitac": 5,
    "dexitac-python": 5,
    "dexitac-e2e": 6,
    "dexitac-benches": 6,
}
PURE = ["dexitac-tactile", "dexitac-gripper"]
PURE_MAY_USE = {"dexitac-protocol"}
FORBIDDEN_IN_PURE = {"minifb", "mcap", "serialport", "linuxvideo", "zune-jpeg", "clap", "image"}


def main() -> int:
    meta = json.loads(
        subprocess.check_output(["cargo", "metadata", "--format-version", "1", "--no-deps", "--locked"])
    )
    errors = []
    members = {p["name"]: p for p in meta["packages"]}
    for name, package in members.items():
        if name not in LAYERS:
            errors.append(f"{name}: not in the crate map (ARCHITECTURE.md, .ci/check-architecture.py)")
            continue
        for dep in package["dependencies"]:
            other = dep["name"]
            if other not in LAYERS or other == name:
                continue
            if LAYERS[other] >= LAYERS[name]:
                errors.append(f"{name} -> {other} ({dep['kind'] or 'normal'}): not a lower layer")
            if name in PURE and other not in PURE_MAY_USE:
                errors.append(f"{name} -> {other}: a pure crate uses only dexitac-protocol")
    for name in PURE:
        tree = subprocess.check_output(
            ["cargo", "tree", "-p", name, "-e", "normal,build,dev", "--prefix", "none", "--locked"],
            text=True,
        )
        used = {line.split()[0] for line in tree.splitlines() if line.strip()}
        for bad in sorted(used & FORBIDDEN_IN_PURE):
            errors.append(f"{name}: cargo tree lists {bad}")
    for e in errors:
        print(f"dependency rule: {e}", file=sys.stderr)
    if not errors:
        print(f"dependency rule holds for {len(members)} crates")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
