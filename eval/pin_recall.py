#!/usr/bin/env python3
"""How many of the renderer's true pins around a press dexitac finds.

    python eval/pin_recall.py --dexitac PATH [--frames DIR] [--stress DIR [--paired]]
        [--seed 1] [--near-px 80] [--match-px 2]

``--frames``: ``render.py``'s ``--out`` folder (its categories);
``--stress``: a folder ``render_stress.py --keep`` wrote (its conditions;
``--paired`` when it was written with ``--paired``).
``dexitac analyze --markers-out`` runs on each, and for every contact frame
the renderer's pins (``render.py``'s ``pins``, from the same seeds) and
dexitac's markers within ``--near-px`` of the truth centre are matched one
to one, nearest pairs first, within ``--match-px``. Prints a markdown row
per category or condition: the pins there, the pins found, the pins
missed, and the markers off every pin (a marker between two pins, or on
none).
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
import render as R  # noqa: E402
import render_stress as RS  # noqa: E402


def match(pins: np.ndarray, markers: np.ndarray, match_px: float) -> tuple[int, int, int]:
    """(found, missed, off): one marker per pin, nearest pairs first."""
    if len(pins) == 0 or len(markers) == 0:
        return 0, len(pins), len(markers)
    d, j = cKDTree(pins).query(markers, distance_upper_bound=match_px)
    used: set[int] = set()
    for dd, jj in sorted(zip(d, j)):
        if dd <= match_px and jj not in used:
            used.add(int(jj))
    return len(used), len(pins) - len(used), len(markers) - len(used)


def score(dexitac: str, folder: Path, contacts, sensor, near_px: float, match_px: float) -> tuple[int, np.ndarray]:
    """Contact frames and (pins, found, missed, off) summed over them."""
    frames = sorted((folder / "frames").glob("*.png"))
    total, n = np.zeros(4, int), 0
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "markers"
        subprocess.run(
            [dexitac, "analyze", "-q", "--rest", str(folder / "rest.png"), "--out", str(Path(tmp) / "pred.csv"),
             "--markers-out", str(out), *map(str, frames)],
            check=True,
        )
        with (folder / "truth.csv").open() as f:
            rows = {r["frame"]: r for r in csv.DictReader(f)}
        for i, _, contact in contacts(len(frames)):
            if contact is None:
                continue
            n += 1
            pins, *_, truth = R.pins(sensor, contact)
            row = rows.get(frames[i].stem)
            if row is None or np.hypot(float(row["cx"]) - truth[0], float(row["cy"]) - truth[1]) > 1e-3:
                sys.exit(f"{folder}: frame {frames[i].stem} is not the contact these options draw; "
                         "give the --seed (and --paired) the frames were rendered with")
            pins = pins[R.in_frame(pins)]
            with open(out / f"{frames[i].stem}.csv") as f:
                markers = np.array([[float(r["x"]), float(r["y"])] for r in csv.DictReader(f)]).reshape(-1, 2)
            near = lambda p: p[np.hypot(*(p - truth).T) < near_px]  # noqa: E731
            pins, markers = near(pins), near(markers)
            total += [len(pins), *match(pins, markers, match_px)]
    return n, total


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", required=True, help="the dexitac binary")
    ap.add_argument("--frames", type=Path, help="render.py's --out folder")
    ap.add_argument("--stress", type=Path, help="a folder render_stress.py --keep wrote")
    ap.add_argument("--seed", type=int, default=1, help="the seed the frames were rendered with")
    ap.add_argument("--paired", action="store_true", help="the --stress frames were written with render_stress.py --paired")
    ap.add_argument("--near-px", type=float, default=80.0, help="pins and markers this near the truth centre count")
    ap.add_argument("--match-px", type=float, default=2.0, help="a pin is found by a marker this near it")
    a = ap.parse_args()
    sets = []
    if a.frames:
        for cat in R.CATEGORIES:
            if cat != "no_contact" and (a.frames / cat / "frames").is_dir():
                sensor = R.sensor_of(cat, a.seed)
                sets.append((cat, a.frames / cat, sensor,
                             lambda k, cat=cat, sensor=sensor: R.frame_contacts(cat, sensor, a.seed, k)))
    if a.stress:
        sensor = R.sensor_of("nominal", a.seed)
        for name in RS.CONDITIONS:
            if (a.stress / name / "frames").is_dir():
                sets.append((name, a.stress / name, sensor,
                             lambda k, name=name: RS.condition_contacts(name, sensor, a.seed, k, a.paired)))
    if not sets:
        ap.error("no frames: give --frames and/or --stress with the folders render.py / render_stress.py wrote")
    print(f"| frames | contact frames | pins within {a.near_px:g} px | found | missed | markers off every pin |")
    print("|---|---|---|---|---|---|")
    for name, folder, sensor, contacts in sets:
        n, (pins, found, missed, off) = score(a.dexitac, folder, contacts, sensor, a.near_px, a.match_px)
        print(f"| {name} | {n} | {pins} | {found} | {missed} | {off} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
