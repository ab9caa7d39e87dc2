#!/usr/bin/env python3
"""How whole a displacement field is, and how well its markers agree.

    python eval/field_quality.py DIR [DIR ...] --pitch-px P

Each ``DIR`` is a ``dexitac analyze --field-out`` folder (one CSV per frame:
``rest_x,rest_y,x,y``; ``x, y`` empty or NaN for a rest marker that was not
paired with a marker of the frame). Real taps have no per-pin truth, so two
numbers stand in for it:

- **lost**: the share of rest markers without a marker in their frame;
- **inconsistent**: the share of paired markers whose displacement differs
  by more than ``--off-pitch`` pitches (default 0.35) from the median
  displacement of the paired markers within ``--near-pitch`` pitches
  (default 1.6) of their rest place (at least 3 of them). A marker paired
  with a neighbouring pin is off by about a pitch; a press's own strain
  changes the displacement by far less between neighbours.

Prints one line per folder.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree


def number(s: str) -> float:
    try:
        return float(s)
    except ValueError:
        return math.nan


def quality(folder: Path, pitch_px: float, near_pitch: float, off_pitch: float) -> dict:
    paired = inconsistent = lost = rest_total = frames = 0
    for f in sorted(folder.glob("*.csv")):
        rows = list(csv.DictReader(open(f)))
        if not rows:
            continue
        frames += 1
        rest = np.array([[number(r["rest_x"]), number(r["rest_y"])] for r in rows])
        now = np.array([[number(r["x"]), number(r["y"])] for r in rows])
        ok = np.isfinite(now).all(axis=1) & np.isfinite(rest).all(axis=1)
        u = now - rest
        rest_total += len(rows)
        lost += int((~ok).sum())
        tree = cKDTree(np.where(np.isfinite(rest), rest, -1e9))
        for i in np.flatnonzero(ok):
            near = [j for j in tree.query_ball_point(rest[i], near_pitch * pitch_px) if j != i and ok[j]]
            if len(near) < 3:
                continue
            paired += 1
            d = u[i] - np.median(u[near], axis=0)
            inconsistent += int(math.hypot(d[0], d[1]) > off_pitch * pitch_px)
    return {"frames": frames, "rest": rest_total, "lost": lost, "judged": paired, "inconsistent": inconsistent}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--pitch-px", type=float, required=True, help="the rest lattice's pitch (analyze logs it)")
    ap.add_argument("--near-pitch", type=float, default=1.6)
    ap.add_argument("--off-pitch", type=float, default=0.35)
    a = ap.parse_args()
    for folder in a.folders:
        q = quality(folder, a.pitch_px, a.near_pitch, a.off_pitch)
        share = lambda n, d: f"{100 * n / d:.1f} %" if d else "–"
        print(f"{folder}: {q['frames']} frames; lost {q['lost']} of {q['rest']} rest markers "
              f"({share(q['lost'], q['rest'])}); inconsistent {q['inconsistent']} of {q['judged']} "
              f"paired markers with 3+ paired neighbours ({share(q['inconsistent'], q['judged'])})")


if __name__ == "__main__":
    main()
