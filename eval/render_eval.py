#!/usr/bin/env python3
"""Score ``dexitac analyze`` on the frames of eval/render.py.

    python eval/render_eval.py --dexitac PATH --frames DIR [--out eval/results] [--date TAG] [--config TOML]

For each category ``DIR/<cat>/`` (rest.png, frames/*.png, truth.csv) it runs
``PATH analyze -q --rest DIR/<cat>/rest.png --out <tmp>/pred.csv DIR/<cat>/frames/*.png``
(no config unless ``--config`` gives one for every category), joins the
prediction with the truth on ``frame`` and reports per category and over all
frames:

- frames;
- markers ±1 %: fraction of frames whose ``n_markers`` is within 1 % of the
  true count, and the median |found - true|;
- contacts found / contact frames (truth centre not NaN, prediction not NaN);
- false contacts: frames without contact (NaN truth) given a centre;
- centre error median and p95 (px, over the contacts found);
- median ``t_total_ms`` (dexitac's own single-thread time of the pipeline).

Prints the markdown table and writes it to ``<out>/<date>-renderer.md``
with the machine, the command and the date.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import fnum, read_csv, run_dexitac  # noqa: E402

TARGETS = (
    "Targets (the issue): markers within ±1 % of the true count, no false contact, "
    "≥97 % of contacts found, centre error median ≤0.5 px and p95 ≤3 px in every category, "
    "median ≤0.25 ms per frame."
)


def machine() -> str:
    model, cores = platform.processor() or platform.machine(), str(os.cpu_count())
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        for line in out.splitlines():
            k, _, v = line.partition(":")
            if k.strip() == "Model name":
                model = v.strip()
            elif k.strip() == "CPU(s)":
                cores = v.strip()
    except OSError:
        pass
    load = ""
    try:
        load = ", load " + " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        pass
    return f"{platform.node()}: {model}, {cores} cores{load}"


# The head of the table of `row`s.
TABLE_HEAD = [
    "| category | frames | markers ±1 % | median \\|found − true\\| (median found / true) | contacts found | "
    "false contacts / no-contact frames | centre err median px | p95 px | t_total ms median |",
    "|---|---|---|---|---|---|---|---|---|",
]


def run_category(dexitac: str, d: Path, config: Path | None = None) -> tuple[list[dict], float, str]:
    """``dexitac analyze --rest rest.png [--config CONFIG]`` on a category's frames (eval/run.py's runner)."""
    with tempfile.TemporaryDirectory() as tmp:
        return run_dexitac(dexitac, d, d / "rest.png", Path(tmp), d.name, config)


def score(pairs: list[tuple[dict, dict]]) -> dict:
    m: dict = {"frames": len(pairs)}
    if not pairs:
        return m
    nt = np.array([fnum(t["n_markers"]) for t, _ in pairs])
    npred = np.array([fnum(p["n_markers"]) if p else math.nan for t, p in pairs])
    err_n = np.abs(npred - nt)
    m["in1"] = float(np.mean(err_n <= 0.01 * nt))
    m["dn_med"] = float(np.nanmedian(err_n)) if np.isfinite(err_n).any() else math.nan
    m["n_true"] = float(np.median(nt))
    m["n_found_med"] = float(np.nanmedian(npred)) if np.isfinite(npred).any() else math.nan
    tc = np.array([[fnum(t["cx"]), fnum(t["cy"])] for t, _ in pairs])
    pc = np.array([[fnum(p["cx"]), fnum(p["cy"])] if p else [math.nan, math.nan] for _, p in pairs])
    has_t = np.isfinite(tc).all(1)
    has_p = np.isfinite(pc).all(1)
    m["contact"] = int(has_t.sum())
    m["found"] = int((has_t & has_p).sum())
    m["free"] = int((~has_t).sum())
    m["false"] = int((~has_t & has_p).sum())
    e = np.hypot(*(pc - tc)[has_t & has_p].T)
    m["errs"] = e
    if len(e):
        m["e_med"] = float(np.median(e))
        m["e_p95"] = float(np.percentile(e, 95))
    t = np.array([fnum(p["t_total_ms"]) if p else math.nan for _, p in pairs])
    m["t_med"] = float(np.nanmedian(t)) if np.isfinite(t).any() else math.nan
    m["t_all"] = t
    return m


def row(name: str, m: dict) -> str:
    f = lambda k, p="{:.2f}": p.format(m[k]) if k in m and not math.isnan(m[k]) else "–"  # noqa: E731
    found = f"{m['found']}/{m['contact']}" if m.get("contact") else "–"
    if m.get("contact"):
        found += f" ({m['found'] / m['contact']:.0%})"
    return (
        f"| {name} | {m['frames']} | {m.get('in1', 0):.0%} | {f('dn_med', '{:.0f}')} "
        f"({f('n_found_med', '{:.0f}')} / {f('n_true', '{:.0f}')}) | {found} | "
        f"{m.get('false', 0)}/{m.get('free', 0)} | {f('e_med')} | {f('e_p95')} | {f('t_med', '{:.3f}')} |"
    )


def sheared(contact: dict) -> bool:
    """Whether a ``contacts.csv`` row's indenter also pushed the skin sideways."""
    return fnum(contact["shear_x_mm"]) != 0 or fnum(contact["shear_y_mm"]) != 0


def shear_cell(pairs: list[tuple[dict, dict]]) -> str:
    """One cell of the shear table: error median / p95 (found / contact frames)."""
    m = score(pairs)
    if "e_med" not in m:
        return f"– ({m.get('found', 0)}/{m.get('contact', 0)})"
    return f"{m['e_med']:.2f} / {m['e_p95']:.2f} ({m['found']}/{m['contact']})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", required=True)
    ap.add_argument("--frames", required=True, help="eval/render.py's --out")
    ap.add_argument("--out", default="eval/results")
    ap.add_argument("--date", default=dt.date.today().isoformat())
    ap.add_argument("--config", type=Path, help="a sensor config for every category (default: none)")
    a = ap.parse_args()
    root, out = Path(a.frames), Path(a.out)
    cats = [p.parent.name for p in sorted(root.glob("*/truth.csv"))]
    order = ["nominal", "flat_nominal", "harsh_light", "blur", "edge", "large", "two_colour", "no_contact"]
    cats = [c for c in order if c in cats] + [c for c in cats if c not in order]
    if not cats:
        print(f"no <category>/truth.csv under {root}", file=sys.stderr)
        return 2
    lines = [
        f"# dexitac on eval/render.py's frames ({a.date})",
        "",
        f"`{' '.join(sys.argv)}`",
        "",
        f"Machine: {machine()}. Frames: `{root}`; `dexitac analyze -q --rest <cat>/rest.png`, "
        + (f"config `{a.config}`." if a.config else "no config."),
        "",
        TARGETS,
        "",
        *TABLE_HEAD,
    ]
    every: list[tuple[dict, dict]] = []
    by_kind: dict[str, list[tuple[dict, dict]]] = {}
    by_shear: dict[str, dict[bool, list[tuple[dict, dict]]]] = {}
    notes = []
    for c in cats:
        d = root / c
        truth = read_csv(d / "truth.csv")
        rows, wall, note = run_category(a.dexitac, d, a.config)
        if note:
            notes.append(f"- {c}: {note}")
        pred = {r["frame"]: r for r in rows}
        missing = [t["frame"] for t in truth if t["frame"] not in pred]
        if missing:
            notes.append(f"- {c}: no prediction for {len(missing)} frame(s): {' '.join(missing[:10])}")
        pairs = [(t, pred.get(t["frame"])) for t in truth]
        every += pairs
        if (d / "contacts.csv").exists():
            contacts = {r["frame"]: r for r in read_csv(d / "contacts.csv")}
            for t, p in pairs:
                if t["frame"] in contacts:
                    by_kind.setdefault(contacts[t["frame"]]["kind"], []).append((t, p))
                    by_shear.setdefault(c, {}).setdefault(sheared(contacts[t["frame"]]), []).append((t, p))
        m = score(pairs)
        lines.append(row(c, m))
        print(f"{c}: {len(rows)} frames in {wall:.1f} s wall", file=sys.stderr)
    lines.append(row("**all**", score(every)))
    if by_kind:
        lines += ["", "Contact frames by indenter (all categories; `contacts.csv`):", "",
                  "| indenter | contact frames | found | centre err median px | p95 px |", "|---|---|---|---|---|"]
        for k, pairs in sorted(by_kind.items()):
            m = score(pairs)
            med = f"{m['e_med']:.2f}" if "e_med" in m else "–"
            p95 = f"{m['e_p95']:.2f}" if "e_p95" in m else "–"
            lines.append(f"| {k} | {m['contact']} | {m['found']} ({m['found'] / max(m['contact'], 1):.0%}) | {med} | {p95} |")
    if by_shear:
        lines += ["", "Contact frames with and without a tangential shear (`contacts.csv`): "
                  "centre error median / p95 px (frames found / contact frames):", "",
                  "| category | without shear | with shear |", "|---|---|---|"]
        for c, groups in by_shear.items():
            lines.append(f"| {c} | {shear_cell(groups.get(False, []))} | {shear_cell(groups.get(True, []))} |")
    if notes:
        lines += ["", "Notes:", *notes]
    text = "\n".join(lines) + "\n"
    print(text)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{a.date}-renderer.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
