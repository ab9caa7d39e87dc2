#!/usr/bin/env python3
"""How well dexitac keeps each pin's identity on eval/render.py's frames.

    python eval/match_quality.py --dexitac target/release/dexitac --frames /tmp/render [--seed 1]

For every category of frames ``render.py`` wrote under ``--frames`` (same
``--seed``), it runs ``dexitac analyze --field-out`` and compares the
displacement field with the renderer's truth: each rest marker is the true
pin nearest to its rest place (within 2 px), and its place in the frame
should be that same pin's pressed place (within 2 px). Per category, over
the contact frames, it prints how many rest markers are

- *right*: in the frame at their own pin;
- *wrong*: in the frame at another pin (a neighbour's blob, or a swap);
- *off*: in the frame, but at no pin (a centroid between two blobs);
- *lost*: without a place in the frame;

first over all rest markers, then over those whose pin moved more than
3 px (the markers a contact's centre is fitted from). The tracked centre,
the shallow and the small-contact rules see only the *right* and the
*wrong* ones.
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
import render as R  # noqa: E402

SAME_PIN_PX, MOVED_PX = 2.0, 3.0
KINDS = ("right", "wrong", "off", "lost")


def read_field(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Rest places (n, 2) and frame places (n, 2; NaN when lost)."""
    rest, now = [], []
    with path.open() as f:
        for row in csv.DictReader(f):
            rest.append((float(row["rest_x"]), float(row["rest_y"])))
            now.append((float(row["x"] or "nan"), float(row["y"] or "nan")))
    return np.array(rest), np.array(now)


def score(rest: np.ndarray, now: np.ndarray, pins_rest: np.ndarray, pins_now: np.ndarray) -> dict:
    """Counts of KINDS over all rest markers that are a pin, and over those whose pin moved."""
    d0, pin = cKDTree(pins_rest).query(rest)
    is_pin = d0 <= SAME_PIN_PX
    found = np.isfinite(now[:, 0])
    d1, at = cKDTree(pins_now).query(np.where(found[:, None], now, 0.0))
    kind = np.full(len(rest), "lost", dtype=object)
    kind[found & (d1 > SAME_PIN_PX)] = "off"
    kind[found & (d1 <= SAME_PIN_PX) & (at != pin)] = "wrong"
    kind[found & (d1 <= SAME_PIN_PX) & (at == pin)] = "right"
    moved = np.hypot(*(pins_now[pin] - pins_rest[pin]).T) > MOVED_PX
    out = {}
    for name, sel in (("all", is_pin), ("moved", is_pin & moved)):
        out[name] = np.array([np.sum(sel & (kind == k)) for k in KINDS])
    return out


def check_seed(folder: Path, truth: dict, frame: str, centre, seed: int) -> None:
    """Exits with a message when ``truth`` (``truth.csv``'s rows by frame)
    does not hold the contact centre that ``seed`` draws for ``frame``: the
    frames were rendered with another ``--seed``, and every pin would be
    compared with the wrong contact."""
    row = truth.get(frame)
    if row is None or math.hypot(float(row["cx"]) - centre[0], float(row["cy"]) - centre[1]) > 1e-3:
        sys.exit(f"{folder}: frame {frame} is not the contact --seed {seed} draws; give the --seed render.py had")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", required=True, help="the dexitac binary")
    ap.add_argument("--frames", required=True, type=Path, help="render.py's --out folder")
    ap.add_argument("--seed", type=int, default=1, help="render.py's --seed")
    ap.add_argument("--categories", nargs="*", default=[c for c in R.CATEGORIES if c != "no_contact"])
    a = ap.parse_args()
    print("| category | contact frames | all: right / wrong / off / lost | pins moved > 3 px | right | wrong | off | lost |")
    print("|---|---|---|---|---|---|---|---|")
    for cat in a.categories:
        folder = a.frames / cat
        frames = sorted((folder / "frames").glob("*.png"))
        sensor = R.sensor_of(cat, a.seed)
        pins_rest, *_ = R.pins(sensor, None)
        totals = {"all": np.zeros(4, int), "moved": np.zeros(4, int)}
        # The pins of each contact frame, checked against truth.csv before
        # dexitac runs.
        with (folder / "truth.csv").open() as f:
            truth = {r["frame"]: r for r in csv.DictReader(f)}
        pressed = []
        for i, _, contact in R.frame_contacts(cat, sensor, a.seed, len(frames)):
            if contact is not None:
                pins_now, *_, centre = R.pins(sensor, contact)
                check_seed(folder, truth, frames[i].stem, centre, a.seed)
                pressed.append((i, pins_now))
        with tempfile.TemporaryDirectory() as tmp:
            field = Path(tmp) / "field"
            subprocess.run(
                [a.dexitac, "analyze", "-q", "--rest", str(folder / "rest.png"), "--out", str(Path(tmp) / "pred.csv"),
                 "--field-out", str(field), *map(str, frames)],
                check=True,
            )
            for i, pins_now in pressed:
                s = score(*read_field(field / f"{frames[i].stem}.csv"), pins_rest, pins_now)
                for k in totals:
                    totals[k] += s[k]
        al, mv = totals["all"], totals["moved"]
        share = lambda v: " | ".join(f"{x} ({100 * x / max(v.sum(), 1):.0f} %)" for x in v)  # noqa: E731
        print(f"| {cat} | {len(pressed)} | {' / '.join(map(str, al))} | {mv.sum()} | {share(mv)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
