#!/usr/bin/env python3
"""Corrections of dexitac's contact centre probed on its own displacement field.

    python eval/centre_probes.py --dexitac BIN --frames DIR [--frames DIR2 ...] [--work TMP]

DIR is ``eval/render.py --out DIR`` output (any seed; ``--no-parallax``
too). For every category of each DIR the script runs ``dexitac analyze
--rest rest.png --field-out`` once (no config: the default centre rules)
and then, in numpy, on the contacts dexitac found, asks whether the field
around dexitac's centre could correct it. Nothing here changes dexitac;
it prints three tables (BENCHMARKS.md, session 37):

- **shear**: the dome's categories but the rim (``nominal``,
  ``harsh_light``, ``blur``, ``two_colour``, ``large``) pooled. The least
  squares fit of the centre error against the renderer's true shear (px of
  error per mm of shear, and what is left of the error once the true shear
  is known), the same fit of the mean displacement of the markers within
  a disc or an annulus around dexitac's centre, that mean's size on the
  unsheared contacts (what a correction by it adds to them), and the
  centre error after adding the mean displacement times the least-squares
  gain.
- **parallax**: every category but the rim; the centre moved by ``-k``
  times the mean displacement within ``R`` px, all of it or only its
  component along the line from the image centre (the pressed pins'
  parallax moves them along it).
- **rim**: the ``edge`` category's errors by the contact's distance from
  the rim (``rim_distance_px`` of ``contacts.csv``), with their radial
  component (from the image centre; negative: inwards).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from centre_floor import scored  # noqa: E402
from render import H, W  # noqa: E402
from run import fnum, read_csv, run_dexitac  # noqa: E402

DOME = ["nominal", "harsh_light", "blur", "two_colour", "large"]
CATEGORIES = DOME + ["flat_nominal", "edge"]
IMAGE_CENTRE = np.array([W, H]) / 2  # as centre_floor.scored takes it


def contacts(frames: Path, work: Path, dexitac: str, cat: str) -> list[dict]:
    """dexitac's found contacts of one category, each with its truth and field."""
    d = frames / cat
    out = work / cat
    out.mkdir(parents=True, exist_ok=True)
    rows, _, err = run_dexitac(dexitac, d, d / "rest.png", out, "default", None,
                               more=("--field-out", str(out / "field")))
    if not rows:
        raise SystemExit(f"dexitac found nothing in {d}: {err}")
    truth = {r["frame"]: r for r in read_csv(d / "truth.csv")}
    info = {r["frame"]: r for r in read_csv(d / "contacts.csv")}
    found = []
    for r in rows:
        f = r["frame"]
        c = np.array([fnum(r["cx"]), fnum(r["cy"])])
        if f not in info or info[f]["kind"] == "none" or not np.isfinite(c).all():
            continue
        field = np.genfromtxt(out / "field" / f"{f}.csv", delimiter=",", skip_header=1, ndmin=2)
        found.append({
            "centre": c,
            "truth": np.array([fnum(truth[f]["cx"]), fnum(truth[f]["cy"])]),
            "rest": field[:, :2],
            "moved": field[:, 2:] - field[:, :2],
            "shear_mm": np.array([fnum(info[f]["shear_x_mm"]), fnum(info[f]["shear_y_mm"])]),
            "rim_px": fnum(info[f]["rim_distance_px"]),
        })
    return found


def mean_move(c: dict, r_in: float, r_out: float, along_ray: bool = False) -> np.ndarray:
    """Mean displacement of the markers whose rest place lies r_in..r_out px
    from dexitac's centre (zero when none); optionally only its component
    along the line from the image centre."""
    d = np.hypot(*(c["rest"] - c["centre"]).T)
    ok = np.isfinite(c["moved"]).all(1) & (d >= r_in) & (d < r_out)
    m = c["moved"][ok].mean(0) if ok.any() else np.zeros(2)
    if along_ray:
        ray = c["centre"] - IMAGE_CENTRE
        ray = ray / max(np.linalg.norm(ray), 1e-9)
        m = (m @ ray) * ray
    return m


def stats(e: np.ndarray) -> str:
    return f"{np.median(e):.2f} / {np.percentile(e, 95):.2f}" if len(e) else "–"


def shear_table(found: list[dict]) -> list[str]:
    err = np.array([c["truth"] - c["centre"] for c in found])
    shear = np.array([c["shear_mm"] for c in found])
    sheared = np.hypot(*shear.T) > 0
    gain, *_ = np.linalg.lstsq(shear[sheared], err[sheared], rcond=None)
    left = np.hypot(*(err[sheared] - shear[sheared] @ gain).T)
    lines = [f"centre error against the true shear: {np.trace(gain) / 2:.2f} px/mm (mean diagonal), "
             f"{np.median(left):.2f} px median left once the shear is known "
             f"({sheared.sum()} sheared, {(~sheared).sum()} unsheared contacts)", "",
             "| markers (px from dexitac's centre) | their mean move per mm of true shear | "
             "mean move, unsheared (median) | centre error, all (median / p95) | unsheared | sheared |",
             "|---|---|---|---|---|---|"]
    base = np.hypot(*err.T)
    lines.append(f"| (no correction) | | | {stats(base)} | {stats(base[~sheared])} | {stats(base[sheared])} |")
    for r_in, r_out in [(0, 20), (15, 35), (25, 50), (50, 90)]:
        m = np.array([mean_move(c, r_in, r_out) for c in found])
        g, *_ = np.linalg.lstsq(shear[sheared], m[sheared], rcond=None)
        k = (m[sheared] * err[sheared]).sum() / max((m[sheared] ** 2).sum(), 1e-12)
        e = np.hypot(*(err - k * m).T)
        lines.append(f"| {r_in}-{r_out} (gain {k:.2f}) | {np.trace(g) / 2:.2f} px | "
                     f"{np.median(np.hypot(*m[~sheared].T)):.2f} px | {stats(e)} | {stats(e[~sheared])} | "
                     f"{stats(e[sheared])} |")
    return lines


def parallax_table(per_cat: dict[str, list[dict]]) -> list[str]:
    cats = [c for c in CATEGORIES if c != "edge" and c in per_cat]
    lines = ["| move by | " + " | ".join(cats) + " |", "|---" * (len(cats) + 1) + "|"]
    for along_ray in (True, False):
        for r_px in (15, 25, 40, 60):
            for k in (0.0, 0.5, 1.0):
                if k == 0.0 and (r_px != 15 or not along_ray):
                    continue
                name = "none" if k == 0.0 else f"-{k} x mean within {r_px} px" + (", along the ray" if along_ray else "")
                cells = []
                for cat in cats:
                    e = [np.linalg.norm(c["centre"] - k * mean_move(c, 0, r_px, along_ray) - c["truth"])
                         for c in per_cat[cat]]
                    cells.append(stats(np.array(e)))
                lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def rim_table(found: list[dict]) -> list[str]:
    lines = ["| rim distance px | contacts | centre error median / p95 px | radial median px |", "|---|---|---|---|"]
    for lo, hi in [(0, 40), (40, 55), (55, 80)]:
        err: list[float] = []
        rad: list[float] = []
        for c in found:
            if lo <= c["rim_px"] < hi:
                scored(c["centre"], c["truth"], err, rad)
        lines.append(f"| {lo}-{hi} | {len(err)} | {stats(np.array(err))} | {np.median(rad):+.2f} |"
                     if err else f"| {lo}-{hi} | 0 | – | – |")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", required=True)
    ap.add_argument("--frames", type=Path, action="append", required=True, help="render.py output (repeatable)")
    ap.add_argument("--work", type=Path, help="keep dexitac's outputs here (default: a temporary folder)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        for frames in args.frames:
            per_cat = {cat: contacts(frames, work / frames.name, args.dexitac, cat)
                       for cat in CATEGORIES if (frames / cat).is_dir()}
            print(f"## {frames}\n")
            print("### shear\n")
            print("\n".join(shear_table([c for cat in DOME if cat in per_cat for c in per_cat[cat]])) + "\n")
            print("### parallax (centre error median / p95 px)\n")
            print("\n".join(parallax_table(per_cat)) + "\n")
            if "edge" in per_cat:
                print("### rim (`edge`)\n")
                print("\n".join(rim_table(per_cat["edge"])) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
