#!/usr/bin/env python3
"""Lay out the public real tactile frames as evaluation sets under data/real/.

Each set becomes

    data/real/<set>/frames/*.png   the frames (8-bit PNG, as in the source or
                                   losslessly re-encoded from its JPEG)
    data/real/<set>/rest.png       a no-contact frame, when the source has one
    data/real/<set>/labels.csv     frame,<label columns the source gives>
    data/real/<set>/set.json       pin count, how it was obtained, source, notes

The sources are git repositories, read either from a work tree (as
eval/get-data.sh clones them, sparse) or from a bare git directory (a
snapshot; files are read with `git show`). Nothing here is committed: the data
sets carry no licence, data/ is git-ignored.

Usage:
    python eval/layout.py --shear PATH --tip PATH --gelslim PATH [--gsrobotics PATH]
        [--out data/real] [--frames 200] [--seed 0]

PATH is a work tree or a bare git directory of
    dexterousrobot/tactile_data_shear            (--shear)
    dexterousrobot/tactile_image_processing      (--tip)
    siyuandong16/gelsight_heightmap_reconstruction (--gelslim)
    gelsightinc/gsrobotics                       (--gsrobotics; GPL-3.0. The
        video is read at commit GS_MINI_COMMIT, which added it: later commits
        removed it, so a work tree must have that commit checked out)
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import random
import shutil
import subprocess
import sys
from pathlib import Path

SHEAR_URL = "https://github.com/dexterousrobot/tactile_data_shear"
TIP_URL = "https://github.com/dexterousrobot/tactile_image_processing"
GELSLIM_URL = "https://github.com/siyuandong16/gelsight_heightmap_reconstruction"
GSROBOTICS_URL = "https://github.com/gelsightinc/gsrobotics"

CR_DIR = "data/cr_tactip/surface_3d/val_data"
FRANKA_DIR = "data/franka_tactip_1/surface_3d/test"
RAW_FRAME = "readme_images/raw_tactile_image.png"
DOTS_DIR = "matlab_version/calibration functions/illumination_calib/Dots1"
GS_MINI_VIDEO = "demos/marker_tracking/data/mini_example.avi"
GS_MINI_COMMIT = "3d1bed69c56d2970d5901a845fdcb3c8da7e9415"

# Pin counts and how they were obtained (see eval/README.md).
TACTIP_PINS = 331
GELSLIM_REF_DOTS = 261
# GelSight's own setting for the GS Mini at 320x240 (N_ = 8 rows, M_ = 10
# columns: demos/mini_tracking_windows_V0/setting.py of gsrobotics).
GS_MINI_DOTS = 80
# A GS Mini frame whose shading differs from the rest over at least this many
# pixels is a contact (the frames after a release keep 0-124).
GS_MINI_CONTACT_AREA_PX = 500


class Source:
    """A git repository read from a work tree or a bare git directory."""

    def __init__(self, path: str, rev: str = "HEAD"):
        self.path = Path(path)
        self.rev = rev
        self.bare = not (self.path / ".git").exists() and (self.path / "HEAD").is_file()
        if not self.bare and not self.path.is_dir():
            sys.exit(f"layout.py: {path}: not a directory")

    def _git(self, *args: str) -> bytes:
        return subprocess.run(
            ["git", f"--git-dir={self.path}", *args], check=True, capture_output=True
        ).stdout

    def commit(self) -> str:
        if self.bare:
            return self._git("rev-parse", self.rev).decode().strip()
        return subprocess.run(
            ["git", "-C", str(self.path), "rev-parse", "HEAD"],
            check=True, capture_output=True, text=True,
        ).stdout.strip()

    def read(self, rel: str) -> bytes:
        if self.bare:
            return self._git("show", f"{self.rev}:{rel}")
        return (self.path / rel).read_bytes()

    def list(self, rel_dir: str) -> list[str]:
        """File names (not paths) directly inside rel_dir."""
        if self.bare:
            out = self._git("ls-tree", "--name-only", self.rev, rel_dir.rstrip("/") + "/")
            return sorted(Path(p).name for p in out.decode().splitlines())
        return sorted(p.name for p in (self.path / rel_dir).iterdir() if p.is_file())


def fresh_dir(d: Path) -> Path:
    if d.exists():
        shutil.rmtree(d)
    (d / "frames").mkdir(parents=True)
    return d


def write_labels(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def write_set(d: Path, meta: dict) -> None:
    (d / "set.json").write_text(json.dumps(meta, indent=2) + "\n")


def shear_set(src: Source, name: str, rel: str, n: int, seed: int, out: Path, meta: dict) -> None:
    """A seeded subset of one split of tactile_data_shear, labels from targets.csv."""
    d = fresh_dir(out / name)
    # targets.csv and targets_images.csv are identical in both splits used
    # here (checked: same rows); their sensor_image column names the files in
    # processed_images/.
    rows = list(csv.DictReader(io.StringIO(src.read(f"{rel}/targets_images.csv").decode())))
    present = set(src.list(f"{rel}/processed_images"))
    rows = [r for r in rows if r["sensor_image"] in present]
    rows.sort(key=lambda r: int(Path(r["sensor_image"]).stem.split("_")[1]))
    pick = sorted(random.Random(seed).sample(range(len(rows)), min(n, len(rows))))
    header = ["frame", "depth_mm", "tilt_x_deg", "tilt_y_deg", "shear_x_mm", "shear_y_mm", "shear_rz_deg"]
    out_rows = []
    for i in pick:
        r = rows[i]
        frame = Path(r["sensor_image"]).stem
        (d / "frames" / f"{frame}.png").write_bytes(src.read(f"{rel}/processed_images/{r['sensor_image']}"))
        out_rows.append([frame, r["pose_z"], r["pose_Rx"], r["pose_Ry"], r["shear_x"], r["shear_y"], r["shear_Rz"]])
    write_labels(d / "labels.csv", header, out_rows)
    meta.update(
        frames=len(out_rows),
        of_split=len(rows),
        seed=seed,
        source_commit=src.commit(),
        labels="pose_z -> depth_mm, pose_Rx -> tilt_x_deg, pose_Ry -> tilt_y_deg, "
        "shear_x/shear_y -> shear_*_mm, shear_Rz -> shear_rz_deg (targets_images.csv)",
        regress_on=["tilt_x_deg", "tilt_y_deg", "depth_mm"],
        rest=None,
        pins_ref_rule="binary_cc: the pins of whichever rest frame eval/run.py uses are the "
        "4-connected regions of white (> 127) pixels of 60-250 px (pins are ~120 px; "
        "smaller specks and merged rim debris are left out)",
    )
    write_set(d, meta)
    print(f"{name}: {len(out_rows)} of {len(rows)} frames")


def write_pins(path: Path, pts) -> None:
    write_labels(path, ["x", "y"], [[f"{x:.2f}", f"{y:.2f}"] for x, y in pts])


def raw_pins(grey):
    """The pins of the raw TacTip frame, by a manual-parameter detector checked
    by eye on an overlay: white top-hat (15 px disc) > 40, regions of at least
    40 px, centroid within 180 px of the pin disc's centre (303, 257), which
    leaves out the LED reflections and specks on the rim and the housing.
    Finds 331 (a top-hat level of 30 or 50 also gives 331)."""
    import cv2
    import numpy as np

    th = cv2.morphologyEx(grey, cv2.MORPH_TOPHAT, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (15, 15)))
    _, _, st, cen = cv2.connectedComponentsWithStats((th > 40).astype(np.uint8))
    a, c = st[1:, cv2.CC_STAT_AREA], cen[1:]
    return c[(a >= 40) & (np.hypot(c[:, 0] - 303, c[:, 1] - 257) < 180)]


def gelslim_dots(bgr):
    """The dots of the GelSlim ref frame, by a manual-parameter detector checked
    by eye on overlays: grey minus its Gaussian blur (sigma 8 px) darker than
    8 levels, 3x3 closing, regions of at least 6 px; the two slivers on the top
    edge (centroid within 2 px of it, dots of the row above the frame) are
    dropped. Finds 261: 14 rows (5 of 18 dots, 9 of 19; row by row linking of
    right-hand neighbours), i.e. the 14 x 19 lattice less the 5 top-right dots
    whose centres lie just outside the frame."""
    import cv2

    c = dark_dots(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), level=8, min_area_px=6)
    return c[c[:, 1] >= 2.0]


def dark_dots(grey, level: float, min_area_px: int):
    """Centroids of the dark dots of a grey image: the regions at least
    `min_area_px` large where it lies more than `level` grey levels below its
    Gaussian blur (sigma 8 px), after a 3x3 closing."""
    import cv2
    import numpy as np

    g = grey.astype(np.float32)
    d = cv2.GaussianBlur(g, (0, 0), 8) - g
    m = cv2.morphologyEx((d > level).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    _, _, st, cen = cv2.connectedComponentsWithStats(m)
    return cen[1:][st[1:, cv2.CC_STAT_AREA] >= min_area_px]


def ball_centre(img, ref) -> tuple[float, float, int]:
    """The imprint of a press on a colour-lit gel (a GelSlim ball press, a
    GelSight Mini finger): centroid and area of the largest region whose
    shading differs from the reference (summed |RGB| difference of the
    sigma-3-blurred frames > 25)."""
    import cv2
    import numpy as np

    a = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 3)
    b = cv2.GaussianBlur(ref.astype(np.float32), (0, 0), 3)
    m = (np.abs(a - b).sum(axis=2) > 25).astype(np.uint8)
    n, _, st, cen = cv2.connectedComponentsWithStats(m)
    if n < 2:
        return float("nan"), float("nan"), 0
    k = 1 + int(np.argmax(st[1:, cv2.CC_STAT_AREA]))
    return float(cen[k][0]), float(cen[k][1]), int(st[k, cv2.CC_STAT_AREA])


def mini_dots(bgr):
    """The dots of the GelSight Mini rest frame, by a manual-parameter detector
    checked by eye on an overlay: brightest channel minus its Gaussian blur
    (sigma 8 px) darker than 12 levels, 3x3 closing, regions of at least 20 px
    (a speck of 10 px on the gel is left out). Finds the 8 x 10 lattice: 7
    full rows (100-125 px a dot) and the top row, which the frame's edge cuts
    through the dots' centres (33-61 px)."""
    return dark_dots(bgr.max(axis=2), level=12, min_area_px=20)


def gs_mini(src: Source, out: Path) -> None:
    """GelSight Mini marker video (gsrobotics): every frame, frame 0 as rest,
    the contact and its centre from the shading (as for gelslim_dots)."""
    import cv2
    import tempfile

    d = fresh_dir(out / "gelsight_mini")
    with tempfile.NamedTemporaryFile(suffix=".avi") as tmp:
        tmp.write(src.read(GS_MINI_VIDEO))
        tmp.flush()
        cap = cv2.VideoCapture(tmp.name)
        frames = []
        while True:
            ok, img = cap.read()
            if not ok:
                break
            frames.append(img)
    if not frames:
        sys.exit(f"layout.py: cannot decode {GS_MINI_VIDEO}")
    ref = frames[0]
    cv2.imwrite(str(d / "rest.png"), ref)
    rows = []
    for k, img in enumerate(frames):
        name = f"{k:04d}"
        cv2.imwrite(str(d / "frames" / f"{name}.png"), img)
        sx, sy, area = ball_centre(img, ref)
        contact = int(area >= GS_MINI_CONTACT_AREA_PX)
        if not contact:
            sx = sy = float("nan")
        rows.append([name, contact, f"{sx:.2f}", f"{sy:.2f}", area])
    write_labels(d / "labels.csv", ["frame", "contact", "shade_x_px", "shade_y_px", "shade_area_px"], rows)
    dots = mini_dots(ref)
    write_pins(d / "pins_ref.csv", dots)
    write_set(d, {
        "name": "gelsight_mini",
        "source": f"{GSROBOTICS_URL} {GS_MINI_VIDEO} (GPL-3.0)",
        "source_commit": src.commit(),
        "size": "320x240 RGB (XVID video, each frame written as PNG)",
        "frames": len(rows),
        "pin_count": GS_MINI_DOTS,
        "pin_count_how": "GelSight's own grid for the GS Mini at 320x240 (8 rows x 10 columns, "
        "gsrobotics demos/mini_tracking_windows_V0/setting.py); layout.py mini_dots finds the "
        "80 on rest.png (pins_ref.csv). The frame's top edge cuts the top row through the "
        "dots' centres (29-53 % of a dot visible): a tool that drops half dots counts 70",
        "pins_ref": "pins_ref.csv: the 80 dot centres of rest.png (layout.py mini_dots)",
        "rest": "rest.png = frame 0000 (no contact; frames 0000-0057 are before the first press)",
        "regress_on": ["shade_x_px", "shade_y_px"],
        "centre_label": ["shade_x_px", "shade_y_px"],
        "labels": "shade_x_px, shade_y_px, shade_area_px: the largest connected region where "
        "the summed |RGB| difference of the frame and rest, both Gaussian-blurred (sigma 3 px), "
        f"exceeds 25, and its centroid; contact = that region has at least "
        f"{GS_MINI_CONTACT_AREA_PX} px (the centre is NaN otherwise). Three finger presses "
        "that slide over the gel (about frames 58-86, 89-153, 160-207); the region is cut by "
        "the frame's edge in the second and third.",
        "notes": "GelSight Mini: dark dots on a colour-lit gel seen flat-on, a square lattice "
        "of about 32 px pitch. No pose label: the shading gives where the finger is.",
    })
    print(f"gelsight_mini: {len(rows)} frames ({sum(r[1] for r in rows)} contacts), "
          f"{len(dots)} reference dots on rest")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shear", required=True, help="tactile_data_shear work tree or bare git dir")
    ap.add_argument("--tip", required=True, help="tactile_image_processing work tree or bare git dir")
    ap.add_argument("--gelslim", required=True, help="gelsight_heightmap_reconstruction work tree or bare git dir")
    ap.add_argument("--gsrobotics", help="gsrobotics work tree (at GS_MINI_COMMIT) or bare git dir")
    ap.add_argument("--out", default="data/real")
    ap.add_argument("--frames", type=int, default=200, help="frames per TacTip shear set")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    shear = Source(args.shear)
    tactip_note = (
        "TacTip, 331 pins (the Bristol TacTip skin; the same count as num_peaks=331 in "
        "tactile_image_processing's PeakDetector). Frames are the Bristol pipeline's "
        "processed images: grey, cropped to bbox, adaptive threshold (61, 5) "
        "-> white pins on black, circle-masked. Every frame is a tap on a flat surface "
        "(depth 0.5/1-6 mm, tilt +-25 deg, shear): there is no no-contact frame."
    )
    shear_set(shear, "tactip_shear_cr", CR_DIR, args.frames, args.seed, out, {
        "name": "tactip_shear_cr",
        "source": f"{SHEAR_URL} {CR_DIR}/processed_images (val_data split)",
        "size": "420x420 grey (bbox [115,10,535,430], circle mask r=210)",
        "pin_count": TACTIP_PINS,
        "pin_count_how": "nominal skin pin count (331)",
        "notes": tactip_note,
    })
    shear_set(shear, "tactip_shear_franka", FRANKA_DIR, args.frames, args.seed, out, {
        "name": "tactip_shear_franka",
        "source": f"{SHEAR_URL} {FRANKA_DIR}/processed_images (test split)",
        "size": "445x440 grey (bbox [105,20,550,460], circle mask r=230)",
        "pin_count": TACTIP_PINS,
        "pin_count_how": "nominal skin pin count (331)",
        "notes": tactip_note,
    })

    tip = Source(args.tip)
    d = fresh_dir(out / "tactip_raw")
    raw = tip.read(RAW_FRAME)
    (d / "frames" / "raw_tactile_image.png").write_bytes(raw)
    (d / "rest.png").write_bytes(raw)
    write_labels(d / "labels.csv", ["frame"], [["raw_tactile_image"]])
    import cv2
    import numpy as np

    pins = raw_pins(cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_GRAYSCALE))
    write_pins(d / "pins_ref.csv", pins)
    write_set(d, {
        "name": "tactip_raw",
        "source": f"{TIP_URL} {RAW_FRAME}",
        "source_commit": tip.commit(),
        "size": "640x480 RGB",
        "frames": 1,
        "pin_count": TACTIP_PINS,
        "pin_count_how": "nominal skin pin count (331); a manual-parameter detector finds "
        "331 pins in this frame (pins_ref.csv, checked by eye, layout.py raw_pins)",
        "pins_ref": "pins_ref.csv: the 331 pin centres of the frame (layout.py raw_pins)",
        "rest": "rest.png (the frame itself: a pin count test, no contact)",
        "regress_on": [],
        "notes": "One raw camera frame: bright pins in a dark disc, bright white housing "
        "around it, LED reflections on the rim. Tests detection on a frame with housing.",
    })
    print(f"tactip_raw: 1 frame, {len(pins)} reference pins")

    gs = Source(args.gelslim)
    d = fresh_dir(out / "gelslim_dots")
    import cv2  # only needed to re-encode the JPEGs losslessly as PNG

    def to_png(rel: str, dst: Path) -> None:
        import numpy as np

        img = cv2.imdecode(np.frombuffer(gs.read(rel), np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            sys.exit(f"layout.py: cannot decode {rel}")
        cv2.imwrite(str(dst), img)

    names = [n for n in gs.list(DOTS_DIR) if n.startswith("sample_") and n.endswith(".jpg")]
    names.sort(key=lambda n: int(n[len("sample_"):-4]))
    to_png(f"{DOTS_DIR}/ref.jpg", d / "rest.png")
    to_png(f"{DOTS_DIR}/ref.jpg", d / "frames" / "ref.png")
    for n in names:
        to_png(f"{DOTS_DIR}/{n}", d / "frames" / (n[:-4] + ".png"))
    rows = [["ref", 0, "nan", "nan", 0]]
    ref = cv2.imread(str(d / "rest.png"))
    dots = gelslim_dots(ref)
    write_pins(d / "pins_ref.csv", dots)
    for n in names:
        bx, by, area = ball_centre(cv2.imread(str(d / "frames" / (n[:-4] + ".png"))), ref)
        rows.append([n[:-4], 1, f"{bx:.2f}", f"{by:.2f}", area])
    write_labels(d / "labels.csv", ["frame", "contact", "ball_x_px", "ball_y_px", "ball_area_px"], rows)
    write_set(d, {
        "name": "gelslim_dots",
        "source": f"{GELSLIM_URL} {DOTS_DIR}/ (ref.jpg + sample_*.jpg)",
        "source_commit": gs.commit(),
        "size": "427x320 RGB (JPEG, re-encoded losslessly as PNG)",
        "frames": len(rows),
        "pin_count": GELSLIM_REF_DOTS,
        "pin_count_how": "counted on ref.jpg (eval/README.md): 14 rows x 19 columns of dots "
        "whose centre lies in the frame, less 5 at the top right whose centre lies just "
        "outside it = 261; 18 of them are half cut by the left and right edges",
        "pins_ref": "pins_ref.csv: the 261 dot centres of ref (layout.py gelslim_dots)",
        "rest": "rest.png = ref.jpg (no contact); ref is also frame 'ref'",
        "regress_on": ["ball_x_px", "ball_y_px"],
        "centre_label": ["ball_x_px", "ball_y_px"],
        "labels": "contact: 0 for ref, 1 for the ball presses; ball_x_px, ball_y_px, "
        "ball_area_px: the ball's imprint, found from the shading alone (not the dots): "
        "largest connected region where the summed |RGB| difference of the frame and ref, "
        "both Gaussian-blurred (sigma 3 px), exceeds 25; its centroid (biased inwards when "
        "the ball is cut by the frame edge). Checked by eye on overlays.",
        "notes": "GelSlim-type sensor, dark printed dots on a bright, colour-lit gel; "
        "sample_* are presses of a ball (a shading calibration set). The source gives no "
        "position label: the ball centre above is derived from the image shading.",
    })
    print(f"gelslim_dots: {len(rows)} frames, {len(dots)} reference dots on ref")

    if args.gsrobotics:
        src = Source(args.gsrobotics, GS_MINI_COMMIT)
        gs_mini(src, out)


if __name__ == "__main__":
    main()
