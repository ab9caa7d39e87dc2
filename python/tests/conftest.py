"""Shared fixtures: the `dexitac` binary and seeded synthetic frames it writes.

The binary is `$DEXITAC_BIN`, else the first of target/{release,debug}/dexitac
under `$CARGO_TARGET_DIR` or the workspace's `target/` (`cargo build -p
dexitac` makes it). The comparisons with the CLI need it: without it they
fail and say so, they do not skip.
"""

from __future__ import annotations

import csv
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import dexitac

WORKSPACE = Path(__file__).resolve().parents[2]


def find_cli() -> Path | None:
    if os.environ.get("DEXITAC_BIN"):
        return Path(os.environ["DEXITAC_BIN"])
    roots = [Path(os.environ["CARGO_TARGET_DIR"])] if os.environ.get("CARGO_TARGET_DIR") else []
    roots.append(WORKSPACE / "target")
    for root in roots:
        for profile in ("release", "debug"):
            exe = root / profile / "dexitac"
            if exe.is_file():
                return exe
    return None


@pytest.fixture(scope="session")
def cli() -> Path:
    exe = find_cli()
    if exe is None:
        pytest.fail("no dexitac binary: set DEXITAC_BIN or run `cargo build -p dexitac` first")
    return exe


def run_cli(cli: Path, *args: str | Path, ok_codes: tuple[int, ...] = (0,)) -> subprocess.CompletedProcess:
    p = subprocess.run([str(cli), "-q", *map(str, args)], capture_output=True, text=True)
    assert p.returncode in ok_codes, f"dexitac {' '.join(map(str, args))}: exit {p.returncode}\n{p.stderr}"
    return p


class Synth:
    """A `dexitac synth-frames` folder: rest.png, frames/NNNN.png."""

    def __init__(self, root: Path):
        self.root = root
        self.rest_path = root / "rest.png"
        self.frame_paths = sorted((root / "frames").glob("*.png"))
        self.rest = dexitac.read_image(self.rest_path)
        self.frames = [dexitac.read_image(p) for p in self.frame_paths]


def make_synth(cli: Path, out: Path, category: str, frames: int, seed: int, size=(640, 480)) -> Synth:
    run_cli(cli, "synth-frames", "--out", out, "--category", category, "--frames", frames,
            "--seed", seed, "--width", size[0], "--height", size[1])
    return Synth(out)


@pytest.fixture(scope="session")
def nominal(cli, tmp_path_factory) -> Synth:
    """640x480 grey frames with contacts (and a few without)."""
    return make_synth(cli, tmp_path_factory.mktemp("nominal"), "nominal", 10, 3)


@pytest.fixture(scope="session")
def large(cli, tmp_path_factory) -> Synth:
    """800x600 frames: rescaled to the 640x480 working frame."""
    return make_synth(cli, tmp_path_factory.mktemp("large"), "large", 6, 5, size=(800, 600))


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def fmt3(v: float) -> str:
    """A coordinate as `dexitac analyze` writes it (3 decimals, NaN)."""
    return "NaN" if not np.isfinite(v) else f"{v:.3f}"
