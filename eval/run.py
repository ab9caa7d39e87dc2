#!/usr/bin/env python3
"""Evaluate dexitac against the usual marker-density tools on real frames.

    python eval/run.py --dexitac target/release/dexitac [--sets A B ...]
        [--data data/real] [--out eval/results] [--rest-modes level median]

For each set laid out by eval/layout.py (data/real/<set>/) and each rest
frame (the set's rest.png when it has one; otherwise, see REST below) it runs

- ``dexitac default``: ``dexitac analyze --rest REST`` with no config (the
  paper's parameters; frames rescaled to the 640x480 working frame);
- ``dexitac tuned``: a base config with the frame's own size as working frame
  and kernel width h = the set's pin pitch, tuned to the known pin count by
  ``dexitac sensor tune --rest REST --pins N``, then ``analyze --config``;
- ``opencv`` and ``doh`` (eval/baselines.py): SimpleBlobDetector /
  skimage blob_doh + the Bristol kernel density + relative-threshold centre,
  h = the set's pin pitch;

and reports per set and tool: markers found against the known pin count,
the fraction of frames with a contact, whether the contact centre follows the
labels (leave-one-out R^2 of a linear regression of centre x and centre y on
the set's regress_on labels, contact frames only) and time per frame.

REST: for a set without rest.png the runner makes one: ``median`` =
pixel-wise median of the set's frames (data/real/<set>/median_rest.png),
``level`` = the lightest, most level tap of the set (smallest
depth/depth_max + (|tilt_x| + |tilt_y|) / 50 deg), copied to
data/real/<set>/level_rest.png. Both are run by default. On the ``median``
rows, when ``dexitac analyze --help`` lists ``--rest-from-frames``,
``dexitac default`` estimates its own rest from the frames instead of using
the median image (the baselines and ``dexitac tuned`` use the image).

The pin pitch (for h) is the median nearest-neighbour distance of the OpenCV
baseline's markers on the rest frame.

Everything runs single-threaded (dexitac's pipeline is single-threaded; the
baselines pin OpenCV/BLAS/OpenMP to one thread). Writes
<out>/<date>.md (the tables) and <out>/<date>/ (CSVs, tuned configs).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import baselines  # noqa: E402

cv2.setNumThreads(1)

ALL_SETS = ["tactip_shear_cr", "tactip_shear_franka", "tactip_raw", "gelslim_dots"]
# Made by eval/raw_taps.py from the sets above; run when present.
DERIVED_SETS = ["tactip_raw_taps", "tactip_raw_taps_light"]
# Laid out by get-data.sh since 2026-11-27 (gsrobotics); run when present, as
# a data folder laid out before has no such set.
OPTIONAL_SETS = ["gelsight_mini"]
TOOLS = ["dexitac default", "dexitac tuned", "opencv", "doh"]


def sh(cmd: list[str]) -> str:
    return subprocess.run(cmd, capture_output=True, text=True).stdout.strip()


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def fnum(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


# ---------------------------------------------------------------- rest frames

def level_tap(labels: list[dict]) -> dict:
    """The lightest, most level tap: smallest depth/depth_max + (|tilt_x| + |tilt_y|) / 50 deg."""
    dmax = max(fnum(r["depth_mm"]) for r in labels)
    return min(labels, key=lambda r: fnum(r["depth_mm"]) / dmax
               + (abs(fnum(r["tilt_x_deg"])) + abs(fnum(r["tilt_y_deg"]))) / 50.0)


def rest_frames(set_dir: Path, meta: dict, modes: list[str]) -> dict[str, Path]:
    if (set_dir / "rest.png").exists():
        return {"rest.png": set_dir / "rest.png"}
    out = {}
    frames = baselines.frame_files(set_dir)
    if "median" in modes:
        p = set_dir / "median_rest.png"
        stack = np.stack([cv2.imread(str(f), cv2.IMREAD_UNCHANGED) for f in frames])
        cv2.imwrite(str(p), np.median(stack, axis=0).round().astype(np.uint8))
        out["median"] = p
    if "level" in modes:
        best = level_tap(read_csv(set_dir / "labels.csv"))
        p = set_dir / "level_rest.png"
        shutil.copyfile(set_dir / "frames" / f"{best['frame']}.png", p)
        meta.setdefault("level_rest_frame", {})[set_dir.name] = (
            f"{best['frame']} (depth {fnum(best['depth_mm']):.2f} mm, tilt "
            f"{fnum(best['tilt_x_deg']):.1f}/{fnum(best['tilt_y_deg']):.1f} deg)")
        out["level"] = p
    return out


def pin_pitch(set_name: str, rest: Path) -> float:
    img = cv2.imread(str(rest), cv2.IMREAD_UNCHANGED)
    pts = baselines.make_opencv(baselines.OPENCV_PARAMS[set_name])(img)
    if len(pts) < 3:
        return 15.0
    d, _ = cKDTree(pts).query(pts, 2)
    return float(np.median(d[:, 1]))


# ---------------------------------------------------------------- tools

def run_dexitac(exe: str, set_dir: Path, rest: Path, out_dir: Path, tag: str,
                config: Path | None, from_frames: bool = False,
                more: tuple[str, ...] = ()) -> tuple[list[dict], float, str]:
    """`from_frames`: dexitac estimates the rest itself (`--rest-from-frames`);
    `more`: further `analyze` options (e.g. `--field-out DIR`)."""
    csv_out = out_dir / f"dexitac_{tag}.csv"
    rest_args = ["--rest-from-frames"] if from_frames else ["--rest", str(rest)]
    cmd = [exe, "analyze", "-q", *rest_args, "--out", str(csv_out), *more]
    if config:
        cmd += ["--config", str(config)]
    cmd.append(str(set_dir / "frames"))
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    note = "" if p.returncode == 0 else f"exit {p.returncode}: {p.stderr.strip()[-300:]}"
    rows = read_csv(csv_out) if csv_out.exists() else []
    return rows, wall, note


def tune_dexitac(exe: str, rest: Path, pins: int, pitch: float, out_dir: Path) -> tuple[Path, str]:
    img = cv2.imread(str(rest), cv2.IMREAD_UNCHANGED)
    h, w = img.shape[:2]
    base = out_dir / "dexitac_base.toml"
    base.write_text(
        "# eval/run.py: the frame's own size as working frame, h = pin pitch\n"
        f"[frame]\nwork_width_px = {w}\nwork_height_px = {h}\n\n"
        f"[density]\nkernel_width_px = {pitch:.2f}\n")
    tuned = out_dir / "dexitac_tuned.toml"
    p = subprocess.run([exe, "sensor", "tune", "--rest", str(rest), "--pins", str(pins),
                        "--config", str(base), "--out", str(tuned)], capture_output=True, text=True)
    msg = " ".join(p.stderr.strip().splitlines()[:1])
    if not tuned.exists():
        return base, f"sensor tune failed (exit {p.returncode}): {msg}"
    return tuned, msg


def run_baseline(kind: str, set_dir: Path, rest: Path, pitch: float, out_dir: Path) -> tuple[list[dict], float]:
    t0 = time.perf_counter()
    rows = baselines.run_set(set_dir, rest, kind, pitch, out_dir / f"{kind}.csv")
    wall = time.perf_counter() - t0
    return [{k: str(v) for k, v in r.items()} for r in rows], wall


def rest_markers(exe: str, tool: str, set_name: str, rest: Path, out_dir: Path,
                 config: Path | None) -> np.ndarray:
    """The markers a tool finds on the rest frame itself (input px)."""
    if tool.startswith("dexitac"):
        mdir = out_dir / f"rest_markers_{tool.split()[1]}"
        shutil.rmtree(mdir, ignore_errors=True)
        cmd = [exe, "analyze", "-q", "--rest", str(rest), "--out", str(out_dir / "rest_only.csv"),
               "--markers-out", str(mdir)]
        if config:
            cmd += ["--config", str(config)]
        subprocess.run(cmd + [str(rest)], capture_output=True, text=True)
        files = list(mdir.glob("*.csv"))
        if not files:
            return np.zeros((0, 2))
        return np.loadtxt(files[0], delimiter=",", skiprows=1, ndmin=2).reshape(-1, 2)
    img = cv2.imread(str(rest), cv2.IMREAD_UNCHANGED)
    make = baselines.make_opencv(baselines.OPENCV_PARAMS[set_name]) if tool == "opencv" \
        else baselines.make_doh(baselines.DOH_PARAMS[set_name])
    return make(img)


def reference_pins(set_dir: Path, meta: dict, rest_name: str, rest: Path) -> np.ndarray | None:
    """Reference pin centres of the rest frame: pins_ref.csv for a set's own
    rest.png, or (binarised TacTip sets, pins_ref_rule binary_cc) the
    4-connected white regions of 60-250 px of whichever rest frame is used."""
    ref_csv = set_dir / "pins_ref.csv"
    if ref_csv.exists() and rest_name == "rest.png":
        return np.loadtxt(ref_csv, delimiter=",", skiprows=1, ndmin=2)
    if str(meta.get("pins_ref_rule", "")).startswith("binary_cc"):
        g = cv2.imread(str(rest), cv2.IMREAD_GRAYSCALE)
        _, _, st, cen = cv2.connectedComponentsWithStats((g > 127).astype(np.uint8), connectivity=4)
        a = st[1:, cv2.CC_STAT_AREA]
        return cen[1:][(a >= 60) & (a <= 250)]
    return None


def position_check(ref: np.ndarray, pts: np.ndarray, pitch: float) -> dict:
    """Markers against the reference pin centres: a pin is found when a marker
    lies within 0.35 pitch of it; a marker is off-pin when no pin lies within
    0.35 pitch, and beyond the pins when none lies within 1 pitch."""
    tol = 0.35 * pitch
    if len(pts) == 0:
        return dict(n=0, found=0, off=0, beyond=0, beyond_at=[])
    d_ref, _ = cKDTree(pts).query(ref)
    d_pts, _ = cKDTree(ref).query(pts)
    beyond = pts[d_pts > pitch]
    return dict(n=len(pts), found=int((d_ref <= tol).sum()), off=int((d_pts > tol).sum()),
                beyond=len(beyond), beyond_at=[(round(float(x)), round(float(y))) for x, y in beyond])


def position_table(rows: list[dict]) -> str:
    lines = ["| set | rest | tool | markers on rest | pins found (of ref) | second markers on a found pin | off-pin markers | of which beyond the pins | where (beyond, px) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        c = r["check"]
        at = " ".join(f"({x},{y})" for x, y in c["beyond_at"][:12])
        if len(c["beyond_at"]) > 12:
            at += f" … {len(c['beyond_at']) - 12} more"
        lines.append(f"| {r['set']} | {r['rest']} | {r['tool']} | {c['n']} | {c['found']}/{r['pins']} | "
                     f"{max(0, c['n'] - c['off'] - c['found'])} | {c['off']} | "
                     f"{c['beyond']} | {at} |")
    return "\n".join(lines)


# ---------------------------------------------------------------- metrics

def loo_r2(y: np.ndarray, X: np.ndarray) -> float:
    """Leave-one-out R^2 of ordinary least squares y ~ [1, X]."""
    n = len(y)
    A = np.column_stack([np.ones(n), X])
    if n <= A.shape[1] + 1:
        return math.nan
    H = A @ np.linalg.pinv(A)
    resid = y - H @ y
    loo = resid / np.clip(1 - np.diag(H), 1e-9, None)
    ss = ((y - y.mean()) ** 2).sum()
    return float(1 - (loo ** 2).sum() / ss) if ss > 0 else math.nan


def metrics(rows: list[dict], labels: list[dict], meta: dict, wall_s: float) -> dict:
    pins = meta["pin_count"]
    lab = {r["frame"]: r for r in labels}
    m = {"frames": len(rows)}
    if not rows:
        return m
    n = np.array([fnum(r["n_markers"]) for r in rows])
    if labels and "pins" in labels[0]:
        # A per-frame pin count (eval/raw_taps.py: the pins each frame has).
        pins = np.array([fnum(lab[r["frame"]]["pins"]) for r in rows])
    err = np.abs(n - pins) / pins
    m.update(n_med=float(np.median(n)), n_min=float(n.min()), n_max=float(n.max()),
             in1=float((err <= 0.01).mean()), in2=float((err <= 0.02).mean()))
    cx = np.array([fnum(r["cx"]) for r in rows])
    cy = np.array([fnum(r["cy"]) for r in rows])
    has = np.isfinite(cx) & np.isfinite(cy)
    m["contact"] = float(has.mean())
    if labels and "contact" in labels[0]:
        truth = np.array([fnum(lab[r["frame"]]["contact"]) for r in rows])
        m["contact_hit"] = f"{int((has & (truth == 1)).sum())}/{int((truth == 1).sum())}"
        m["contact_false"] = f"{int((has & (truth == 0)).sum())}/{int((truth == 0).sum())}"
    reg = meta.get("regress_on") or []
    if reg:
        X = np.array([[fnum(lab[r["frame"]][c]) for c in reg] for r in rows])
        # Frames without labels (a rest frame's NaN ball position) are out.
        sel = has & np.isfinite(X).all(axis=1)
        m["r2_n"] = int(sel.sum())
        if sel.sum() >= 10:
            m["r2x"] = loo_r2(cx[sel], X[sel])
            m["r2y"] = loo_r2(cy[sel], X[sel])
    cl = meta.get("centre_label")
    if cl:
        L = np.array([[fnum(lab[r["frame"]][c]) for c in cl] for r in rows])
        ok = has & np.isfinite(L).all(axis=1)
        if ok.any():
            m["err_med"] = float(np.median(np.hypot(cx[ok] - L[ok, 0], cy[ok] - L[ok, 1])))
    for key, col in (("t_det", "t_detect_ms"), ("t_kde", "t_kde_ms"),
                     ("t_cen", "t_segment_ms" if "t_segment_ms" in rows[0] else "t_centre_ms")):
        m[key] = float(np.median([fnum(r.get(col)) for r in rows]))
    t = np.array([fnum(r["t_total_ms"]) for r in rows])
    m.update(t_med=float(np.median(t)), t_p95=float(np.percentile(t, 95)),
             wall_ms=wall_s * 1e3 / len(rows))
    return m


# ---------------------------------------------------------------- report

def fmt(v, spec=".2f", none="–"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    return format(v, spec)


def table(results: list[dict]) -> str:
    head = ("| set | rest | tool | frames | markers median [min–max] / pins | ±1 % | ±2 % | "
            "contact frames | R² x | R² y | centre err px | ms/frame median | p95 | wall ms/frame | notes |")
    lines = [head, "|" + "---|" * 15]
    for r in results:
        m = r["m"]
        if "n_med" in m:
            mk = f"{m['n_med']:.0f} [{m['n_min']:.0f}–{m['n_max']:.0f}] / {r['pins']}"
        else:
            mk = "–"
        contact = fmt(m.get("contact"), ".0%")
        if "contact_hit" in m:
            contact = f"{m['contact_hit']} presses, {m['contact_false']} on ref"
        lines.append(
            f"| {r['set']} | {r['rest']} | {r['tool']} | {m.get('frames', 0)} | {mk} | "
            f"{fmt(m.get('in1'), '.0%')} | {fmt(m.get('in2'), '.0%')} | {contact} | "
            f"{fmt(m.get('r2x'))} | {fmt(m.get('r2y'))} | {fmt(m.get('err_med'), '.1f')} | {fmt(m.get('t_med'))} | "
            f"{fmt(m.get('t_p95'))} | {fmt(m.get('wall_ms'))} | {r.get('note', '')} |")
    return "\n".join(lines)


def stage_table(results: list[dict]) -> str:
    lines = ["| set | rest | tool | detect ms | density ms | region + centre ms | total ms |",
             "|---|---|---|---|---|---|---|"]
    for r in results:
        m = r["m"]
        lines.append(f"| {r['set']} | {r['rest']} | {r['tool']} | {fmt(m.get('t_det'))} | "
                     f"{fmt(m.get('t_kde'))} | {fmt(m.get('t_cen'))} | {fmt(m.get('t_med'))} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", default="target/release/dexitac")
    ap.add_argument("--sets", nargs="+", default=None,
                    help=f"default: {' '.join(ALL_SETS)}, and {' '.join(DERIVED_SETS + OPTIONAL_SETS)} "
                    "when laid out")
    ap.add_argument("--data", type=Path, default=Path("data/real"))
    ap.add_argument("--out", type=Path, default=Path("eval/results"))
    ap.add_argument("--rest-modes", nargs="+", default=["level", "median"], choices=["level", "median"],
                    help="rest frames for sets without rest.png")
    ap.add_argument("--date", default=dt.date.today().isoformat())
    ap.add_argument("--dexitac-config", type=Path,
                    help="a sensor config for the 'dexitac default' rows (default: none)")
    ap.add_argument("--tools", nargs="+", default=TOOLS, choices=TOOLS,
                    help="run only these tools (e.g. dexitac after a change, the baselines unchanged)")
    a = ap.parse_args()
    if a.sets is None:
        a.sets = ALL_SETS + [s for s in DERIVED_SETS + OPTIONAL_SETS
                             if (a.data / s / "set.json").exists()]
    exe = str(Path(a.dexitac).resolve())
    if not Path(exe).is_file():
        sys.exit(f"run.py: no dexitac binary at {a.dexitac}: build it with "
                 "cargo build --release -p dexitac")
    helptext = sh([exe, "analyze", "--help"])
    rest_from_frames = "--rest-from-frames" in helptext
    work = a.out / a.date
    work.mkdir(parents=True, exist_ok=True)
    up_before = sh(["uptime"])
    notes: dict = {}
    results = []
    positions: list[dict] = []
    for s in a.sets:
        set_dir = a.data / s
        meta = json.loads((set_dir / "set.json").read_text())
        labels = read_csv(set_dir / "labels.csv")
        for rest_name, rest in rest_frames(set_dir, notes, a.rest_modes).items():
            out_dir = work / s / rest_name.replace(".png", "")
            out_dir.mkdir(parents=True, exist_ok=True)
            pitch = pin_pitch(s, rest)
            notes.setdefault("pitch", {})[f"{s}/{rest_name}"] = round(pitch, 2)
            print(f"{s} rest={rest_name}: pitch {pitch:.1f} px", file=sys.stderr)
            base = dict(set=s, rest=rest_name, pins=meta["pin_count"])
            # For the median rest, dexitac makes its own from the frames when
            # it can (`--rest-from-frames`); the baselines use the median image.
            own = rest_from_frames and rest_name == "median"
            if "dexitac default" in a.tools:
                rows, wall, note = run_dexitac(exe, set_dir, rest, out_dir, "default", a.dexitac_config, from_frames=own)
                if own:
                    note = (note + " " if note else "") + "rest: --rest-from-frames"
                results.append(dict(base, tool="dexitac default", m=metrics(rows, labels, meta, wall), note=note))
            cfg = None
            if "dexitac tuned" in a.tools:
                cfg, tune_msg = tune_dexitac(exe, rest, meta["pin_count"], pitch, out_dir)
                notes.setdefault("tune", {})[f"{s}/{rest_name}"] = tune_msg
                rows, wall, note = run_dexitac(exe, set_dir, rest, out_dir, "tuned", cfg)
                results.append(dict(base, tool="dexitac tuned", m=metrics(rows, labels, meta, wall), note=note))
            for kind in ("opencv", "doh"):
                if kind in a.tools:
                    rows, wall = run_baseline(kind, set_dir, rest, pitch, out_dir)
                    results.append(dict(base, tool=kind, m=metrics(rows, labels, meta, wall)))
            ref = reference_pins(set_dir, meta, rest_name, rest)
            if ref is not None:
                for tool in a.tools:
                    pts = rest_markers(exe, tool, s, rest, out_dir, cfg if tool == "dexitac tuned" else a.dexitac_config)
                    positions.append(dict(set=s, rest=rest_name, tool=tool, pins=len(ref),
                                          check=position_check(ref, pts, pitch)))
            print(table([r for r in results if r["set"] == s and r["rest"] == rest_name]), file=sys.stderr)
    up_after = sh(["uptime"])
    lscpu = sh(["sh", "-c", "lscpu | grep -m1 'Model name' | sed 's/.*: *//'"])
    md = [f"# Real frames: dexitac against OpenCV / scikit-image ({a.date})", "",
          f"- Machine: {lscpu or platform.processor()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, OpenCV {cv2.__version__}, "
          f"scikit-image {__import__('skimage').__version__}, numpy {np.__version__}",
          f"- dexitac: `{a.dexitac}` ({sh([exe, '--version'])}); "
          f"`analyze --help` lists --rest-from-frames: {'yes' if rest_from_frames else 'no'} "
          "(rest frames for sets without rest.png are made by this runner; with the option, "
          "`dexitac default` on the `median` rows estimates its own rest from the frames)",
          f"- Load before: `{up_before}`", f"- Load after: `{up_after}`",
          "- Single-threaded: dexitac's pipeline has no threads; the baselines run with "
          "cv2.setNumThreads(1) and OMP/OPENBLAS/MKL threads 1.",
          f"- Command: `python eval/run.py --dexitac {a.dexitac} --sets {' '.join(a.sets)}`", "",
          table(results), "",
          "Rest frame against reference pin centres (pins_ref.csv of the set's rest.png; for the "
          "binarised TacTip sets the 4-connected white regions of 60-250 px of the rest frame used): "
          "a pin is found when a marker lies within 0.35 pitch; second markers = markers near a pin "
          "beyond one per found pin; off-pin = markers with no pin "
          "within 0.35 pitch; beyond = no pin within 1 pitch (on the rim, housing or LEDs).", "",
          position_table(positions) if positions else "(no set with pins_ref.csv)", "",
          "Columns: markers = per-frame marker count (median [min–max]) against the known pin "
          "count; ±1 %/±2 % = fraction of frames whose count is that close; contact frames = "
          "fraction of frames with a contact centre; R² = leave-one-out R² of a linear "
          "regression of the centre x (y) on the set's labels (regress_on in set.json), "
          "contact frames only; centre err = median distance from the centre to the labelled "
          "contact centre (gelslim: the ball imprint, gelsight_mini: the finger, both found "
          "from the shading); ms/frame = "
          "the tool's own per-frame time (dexitac: its t_total_ms column, preparation + "
          "pipeline; baselines: perf_counter around detection + density + centre); wall "
          "= process (dexitac) or loop (baselines, with decoding) time / frames, including the "
          "rest calibration.", "",
          "Per stage, median ms per frame (dexitac: its CSV's t_detect_ms (with frame "
          "preparation), t_kde_ms, t_segment_ms; baselines: detection, density, centre):", "",
          stage_table(results), "",
          "```json", json.dumps(notes, indent=1), "```", ""]
    report = a.out / f"{a.date}.md"
    report.write_text("\n".join(md))
    print("\n".join(md))
    print(f"wrote {report}", file=sys.stderr)


if __name__ == "__main__":
    main()
