#!/usr/bin/env python3
"""Time `dexitac.Sensor.process` against the usual Python pipelines, in one run.

    python python/bench.py --dexitac target/release/dexitac [--frames 40] [--seed 1]
        [--rounds 5] [--set-dir data/real/SET [--rest REST.png] [--max-frames N]]
        [--out table.md]

On the same frames (numpy arrays decoded once beforehand), single-threaded,
one tool after the other:

- ``dexitac (Python)``: ``Sensor.process(frame)``, wall clock around the call
  (``time.perf_counter``), so it includes the binding: the array checks, the
  GIL release and the result arrays;
- ``dexitac (Rust, in process)``: the ``times.total_ms`` the same calls report,
  measured inside Rust (preparation + pipeline);
- ``dexitac analyze (CLI)``: the ``t_total_ms`` of ``dexitac analyze`` on the
  same files (a separate process, same library functions), one run after
  each Python pass so that both see the same load;
- ``opencv`` and ``doh``: eval/baselines.py (OpenCV SimpleBlobDetector /
  scikit-image blob_doh, each + the Bristol numpy kernel density + the
  relative-threshold centre), reused, not rewritten: the same code
  eval/run.py times on the real data sets.

Frames: ``dexitac synth-frames --frames N --seed S`` (640x480, bright pins,
one contact each, with ground truth), or with ``--set-dir`` a real set laid
out by eval/layout.py (its rest.png and frames/*.png; baseline parameters of
eval/baselines.py for that set). Prints a Markdown table (also to --out):
per tool the median and 95th percentile time per frame, the speed-up of
dexitac over it, frames with a contact and, on synthetic frames, the median
centre error against the truth.

Needs numpy, opencv-python(-headless), scikit-image, scipy and the dexitac
package. BLAS/OpenMP/OpenCV are pinned to one thread by eval/baselines.py.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "eval"))

import baselines  # noqa: E402  (sets the thread counts before numpy/cv2 load)
import numpy as np  # noqa: E402

import dexitac  # noqa: E402

# Baseline detector parameters for the `dexitac synth-frames` frames (bright
# pins of 6-8 px on a dark skin, 15 px pitch): both find the 756 pins of the
# seed-1 rest frame, as dexitac's calibration does.
SYNTH = "dexitac_synth"
baselines.OPENCV_PARAMS.setdefault(SYNTH, dict(
    minThreshold=30, maxThreshold=230, thresholdStep=10, filterByColor=True, blobColor=255,
    filterByArea=True, minArea=8, maxArea=120, filterByCircularity=True, minCircularity=0.6,
    filterByInertia=True, minInertiaRatio=0.3, filterByConvexity=True, minConvexity=0.8))
baselines.DOH_PARAMS.setdefault(SYNTH, dict(min_sigma=2.0, max_sigma=4.0, num_sigma=5, threshold=0.01))


def stats(ms: list[float]) -> tuple[float, float]:
    v = np.sort(np.asarray(ms))
    return float(np.median(v)), float(v[min(len(v) - 1, math.ceil(0.95 * len(v)) - 1)])


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dexitac", type=Path, required=True, help="the dexitac binary (synth-frames, analyze)")
    ap.add_argument("--frames", type=int, default=40, help="synthetic frames")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rounds", type=int, default=5, help="passes of dexitac over the frames (baselines: 1)")
    ap.add_argument("--thread-rounds", type=int, default=20,
                    help="passes of each of two sensors over the frames, one thread then two")
    ap.add_argument("--set-dir", type=Path, help="a real set (rest.png, frames/*.png) instead of synthetic frames")
    ap.add_argument("--rest", type=Path, help="with --set-dir: the rest frame (default SET/rest.png)")
    ap.add_argument("--max-frames", type=int, help="with --set-dir: only the first N frames (name order)")
    ap.add_argument("--kernel-px", type=float, default=15.0, help="baselines' kernel width h, px")
    ap.add_argument("--out", type=Path, help="also write the table here")
    a = ap.parse_args()

    load_before = uptime()
    tmp = Path(tempfile.mkdtemp(prefix="dexitac-bench-"))
    truth: dict[str, tuple[float, float]] = {}
    if a.set_dir:
        set_name, rest_path = a.set_dir.name, a.rest or a.set_dir / "rest.png"
        frame_paths = sorted((a.set_dir / "frames").glob("*.png"))[: a.max_frames]
    else:
        set_name, rest_path = SYNTH, tmp / "rest.png"
        subprocess.run([str(a.dexitac), "-q", "synth-frames", "--out", str(tmp), "--frames", str(a.frames),
                        "--seed", str(a.seed)], check=True)
        frame_paths = sorted((tmp / "frames").glob("*.png"))
        with open(tmp / "truth.csv", newline="") as f:
            truth = {r["frame"]: (float(r["cx"]), float(r["cy"])) for r in csv.DictReader(f)}
    rest = dexitac.read_image(rest_path)
    frames = [dexitac.read_image(p) for p in frame_paths]
    names = [p.stem for p in frame_paths]

    # dexitac from Python and the CLI on the same files, round after round
    # (each round: one pass of `process` over the frames, then one `dexitac
    # analyze` run), so that both see the same machine load.
    sensor = dexitac.Sensor.from_rest(rest)
    py_ms: list[float] = []
    rust_ms: list[float] = []
    cli_ms: list[float] = []
    detect_ms: dict[str, list[float]] = {"dexitac": [], "cli": []}
    centres: dict[str, dict[str, tuple[float, float]]] = {"dexitac": {}}
    pred = tmp / "pred.csv"
    for _ in range(a.rounds):
        for name, f in zip(names, frames):
            t0 = time.perf_counter()
            obs = sensor.process(f)
            py_ms.append((time.perf_counter() - t0) * 1e3)
            rust_ms.append(obs.times.total_ms)
            detect_ms["dexitac"].append(obs.times.detect_ms)
            if obs.contact:
                centres["dexitac"][name] = obs.contact.centre_px
        subprocess.run([str(a.dexitac), "-q", "analyze", "--rest", str(rest_path), "--out", str(pred),
                        *map(str, frame_paths)], check=True)
        with open(pred, newline="") as f:
            cli_rows = list(csv.DictReader(f))
        cli_ms += [float(r["t_total_ms"]) for r in cli_rows]
        detect_ms["cli"] += [float(r["t_detect_ms"]) for r in cli_rows]

    # Two sensors: one after the other in one thread, then in two threads
    # (`process` releases the GIL); best of three tries each, alternating.
    pair = [sensor, dexitac.Sensor.from_rest(rest)]

    def work(s: dexitac.Sensor) -> None:
        for _ in range(a.thread_rounds):
            for f in frames:
                s.process(f)

    one_thread_s = two_threads_s = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for s in pair:
            work(s)
        one_thread_s = min(one_thread_s, time.perf_counter() - t0)
        threads = [threading.Thread(target=work, args=(s,)) for s in pair]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        two_threads_s = min(two_threads_s, time.perf_counter() - t0)

    # The baselines, one round each (they take 20-500 ms per frame).
    base_ms: dict[str, list[float]] = {}
    for kind in ("opencv", "doh"):
        b = baselines.Baseline(kind, set_name, a.kernel_px, rest.shape[:2])
        b.calibrate(rest)
        base_ms[kind] = []
        detect_ms[kind] = []
        centres[kind] = {}
        for name, f in zip(names, frames):
            r = b.run(f)
            base_ms[kind].append(r.t_total_ms)
            detect_ms[kind].append(r.t_detect_ms)
            if math.isfinite(r.cx):
                centres[kind][name] = (r.cx, r.cy)
    load_after = uptime()

    def err(tool: str) -> str:
        if not truth:
            return "-"
        e = [math.dist(c, truth[n]) for n, c in centres[tool].items() if n in truth and math.isfinite(truth[n][0])]
        return f"{np.median(e):.2f}" if e else "-"

    py_med, _ = stats(py_ms)
    rows = [
        ("dexitac (Python: `Sensor.process`, wall clock)", py_ms, "dexitac", "dexitac"),
        ("dexitac (Rust, same calls: `times.total_ms`)", rust_ms, "dexitac", "dexitac"),
        ("dexitac analyze (CLI: `t_total_ms`)", cli_ms, "dexitac", "cli"),
        ("OpenCV SimpleBlobDetector + numpy KDE (eval/baselines.py)", base_ms["opencv"], "opencv", "opencv"),
        ("scikit-image blob_doh + numpy KDE (eval/baselines.py)", base_ms["doh"], "doh", "doh"),
    ]
    n = len(frames)
    lines = [
        f"Frames: {'synthetic, `dexitac synth-frames --frames %d --seed %d`' % (a.frames, a.seed) if not a.set_dir else a.set_dir} "
        f"({n} frames, {rest.shape[1]}x{rest.shape[0]} px); dexitac and the CLI {a.rounds} rounds each, interleaved, baselines 1; single thread.",
        "",
        "| tool | ms/frame median | ms/frame p95 | Python dexitac faster by | detection ms median "
        "| frames with contact | centre error median px |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, ms, tool, detect in rows:
        med, p95 = stats(ms)
        found = len(centres[tool])
        lines.append(f"| {label} | {med:.3f} | {p95:.3f} | {med / py_med:.1f}x | {stats(detect_ms[detect])[0]:.3f} "
                     f"| {found}/{n} | {err(tool)} |")
    lines += [
        "",
        f"Python wall clock over the Rust time of the same calls: {py_med / stats(rust_ms)[0]:.3f}; "
        f"over the CLI's: {py_med / stats(cli_ms)[0]:.3f}.",
        f"Two sensors, {a.thread_rounds} x {n} frames each (best of 3): one thread {one_thread_s:.2f} s, two threads "
        f"{two_threads_s:.2f} s ({one_thread_s / two_threads_s:.2f}x; {len(os.sched_getaffinity(0))} CPUs usable).",
        f"Machine: {cpu_model()}, {platform.machine()}, Python {platform.python_version()}, "
        f"numpy {np.__version__}, OpenCV {baselines.cv2.__version__}, dexitac {dexitac.__version__}.",
        f"Date: {datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}.",
        f"Load (uptime) before: `{load_before}`; after: `{load_after}`.",
    ]
    text = "\n".join(lines)
    print(text)
    if a.out:
        a.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
