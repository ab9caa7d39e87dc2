"""The Python package gives what `dexitac analyze`, `record` and `sensor`
give on the same frames, to the last digit the CLI writes (and bit for bit
against the exact centres a recording stores)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dexitac
from conftest import fmt3, read_csv, run_cli


def analyze_csv(cli: Path, out: Path, *args) -> dict[str, dict[str, str]]:
    run_cli(cli, "analyze", "--out", out / "pred.csv", "--markers-out", out / "markers", *args)
    return {row["frame"]: row for row in read_csv(out / "pred.csv")}


def assert_row_matches(row: dict[str, str], obs: dexitac.Observation, markers_csv: Path) -> None:
    c = obs.contact
    assert row["cx"] == fmt3(c.centre_px[0] if c else np.nan)
    assert row["cy"] == fmt3(c.centre_px[1] if c else np.nan)
    assert row["area_mm2"] == (f"{c.area_mm2:.3f}" if c else "0")
    assert row["source"] == (c.source if c else "none")
    assert int(row["n_markers"]) == obs.n_markers == len(obs.markers_px)
    assert row["skipped"] == str(obs.skipped).lower()
    got = [f"{x:.3f},{y:.3f}" for x, y in obs.markers_px]
    want = markers_csv.read_text().splitlines()[1:]
    assert got == want


@pytest.mark.parametrize("fixture", ["nominal", "large"])
def test_process_matches_analyze(fixture, cli, tmp_path, request):
    s = request.getfixturevalue(fixture)
    rows = analyze_csv(cli, tmp_path, "--rest", s.rest_path, *s.frame_paths)
    sensor = dexitac.Sensor.from_rest(s.rest)
    contacts = 0
    # The shift columns: `analyze` holds the first contact as the anchor.
    tracker = dexitac.ShiftTracker(sensor.mm_per_px)
    mm = lambda v: "NaN" if v is None else f"{v:.4f}"  # noqa: E731
    for path, frame in zip(s.frame_paths, s.frames):
        obs = sensor.process(frame)
        contacts += obs.contact is not None
        row = rows[path.stem]
        assert_row_matches(row, obs, tmp_path / "markers" / f"{path.stem}.csv")
        shift = tracker.update(obs)
        from_anchor = shift.from_anchor_mm
        if obs.contact is not None and from_anchor is None:
            assert tracker.hold_anchor()
            from_anchor = 0.0
        assert row["shift_mm"] == mm(shift.frame_to_frame_mm)
        assert row["shift_from_anchor_mm"] == mm(from_anchor)
    assert contacts >= len(s.frames) // 2, "the comparison must cover contacts"


def half(img: np.ndarray) -> np.ndarray:
    """A 640x480 frame halved (2x2 block means): the pins 7.5 px apart,
    under the detector's 11 px."""
    return (img.reshape(240, 2, 320, 2).mean(axis=(1, 3)) + 0.5).astype(np.uint8)


def write_frames(folder: Path, frames: list[np.ndarray]) -> list[Path]:
    paths = [folder / f"{k:04d}.png" for k in range(len(frames))]
    for path, frame in zip(paths, frames):
        write_png(path, frame)
    return paths


def assert_magnified_rows_match(sensor, rows, paths, frames, markers: Path, min_contacts: int) -> None:
    # Both magnify the working frame alike, so the rows are the same; the
    # millimetres per pixel follow the magnification.
    assert sensor.mm_per_px < 0.1 * 0.75, sensor.mm_per_px
    contacts = 0
    for path, frame in zip(paths, frames):
        obs = sensor.process(frame)
        contacts += obs.contact is not None
        assert_row_matches(rows[path.stem], obs, markers / f"{path.stem}.csv")
    assert contacts >= min_contacts, "the comparison must cover contacts"


def test_pins_too_close_are_magnified_as_in_analyze(nominal, cli, tmp_path):
    rest, frames = half(nominal.rest), [half(f) for f in nominal.frames[:4]]
    rest_path = tmp_path / "rest.png"
    write_png(rest_path, rest)
    paths = write_frames(tmp_path, frames)
    rows = analyze_csv(cli, tmp_path, "--rest", rest_path, *paths)
    assert_magnified_rows_match(dexitac.Sensor.from_rest(rest), rows, paths, frames, tmp_path / "markers", 2)


def test_a_rest_from_close_pins_is_magnified_as_in_analyze(nominal, cli, tmp_path):
    frames = [half(f) for f in nominal.frames]
    paths = write_frames(tmp_path, frames)
    rows = analyze_csv(cli, tmp_path, "--rest-from-frames", *paths)
    sensor = dexitac.Sensor.from_rest_frames(frames)
    assert_magnified_rows_match(sensor, rows, paths, frames, tmp_path / "markers", len(frames) // 2)


def test_several_rest_frames_match_analyze(nominal, cli, tmp_path):
    # `--rest A --rest B`: markers found in every rest frame, averaged. The
    # second rest frame is the first with its pixels' lowest bit flipped.
    other = tmp_path / "rest2.png"
    rest2 = nominal.rest ^ np.uint8(1)
    write_png(other, rest2)
    frames = nominal.frame_paths[:4]
    rows = analyze_csv(cli, tmp_path, "--rest", nominal.rest_path, "--rest", other, *frames)
    sensor = dexitac.Sensor.from_rest([nominal.rest, rest2])
    for path, frame in zip(frames, nominal.frames):
        assert_row_matches(rows[path.stem], sensor.process(frame), tmp_path / "markers" / f"{path.stem}.csv")


def test_config_crop_and_rgb_match_analyze(nominal, cli, tmp_path):
    # A crop and a kernel width from a config file; the frames as RGB.
    config = tmp_path / "sensor.toml"
    config.write_text('[frame]\ncrop_px = [40, 20, 560, 440]\n\n[density]\nkernel_width_px = 13.0\n')
    rgb_dir = tmp_path / "rgb"
    rgb_dir.mkdir()
    rgb = [np.ascontiguousarray(np.stack([f, f, f], axis=-1)) for f in [nominal.rest, *nominal.frames]]
    # The same RGB frames on disk for the CLI, written by the package's own
    # PNG reader's counterpart: a minimal PNG writer (no extra dependency).
    paths = []
    for k, img in enumerate(rgb):
        p = rgb_dir / f"{k:04d}.png"
        write_png(p, img)
        assert np.array_equal(dexitac.read_image(p), img)
        paths.append(p)
    rows = analyze_csv(cli, tmp_path, "--rest", paths[0], "--config", config, *paths[1:])
    sensor = dexitac.Sensor.from_rest(rgb[0], config=config)
    same_as_text = dexitac.Sensor.from_rest(rgb[0], config=config.read_text())
    same_as_dict = dexitac.Sensor.from_rest(
        rgb[0], config={"frame": {"crop_px": [40, 20, 560, 440]}, "density": {"kernel_width_px": 13.0}})
    assert sensor.work_size_px == (560, 440)
    for p, img in zip(paths[1:], rgb[1:]):
        obs = sensor.process(img)
        assert_row_matches(rows[p.stem], obs, tmp_path / "markers" / f"{p.stem}.csv")
        for other in (same_as_text, same_as_dict):
            o = other.process(img)
            assert np.array_equal(o.markers_px, obs.markers_px)
            assert (o.contact and o.contact.centre_px) == (obs.contact and obs.contact.centre_px)


def test_rest_from_frames_matches_analyze(nominal, cli, tmp_path):
    rows = analyze_csv(cli, tmp_path, "--rest-from-frames", *nominal.frame_paths)
    sensor = dexitac.Sensor.from_rest_frames(nominal.frames)
    for path, frame in zip(nominal.frame_paths, nominal.frames):
        assert_row_matches(rows[path.stem], sensor.process(frame), tmp_path / "markers" / f"{path.stem}.csv")


def test_centres_match_a_recording_bit_for_bit(nominal, cli, tmp_path):
    # `dexitac record` runs the Rust pipeline on a frame folder (the first
    # frame in name order is the rest) and stores each centre as an exact f64.
    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "0000.png").write_bytes(nominal.rest_path.read_bytes())
    for k, p in enumerate(nominal.frame_paths):
        (folder / f"{k + 1:04d}.png").write_bytes(p.read_bytes())
    mcap = tmp_path / "run.mcap"
    run_cli(cli, "record", "--out", mcap, "--frames", folder, "--max-speed")
    rec = dexitac.read_recording(mcap)
    assert rec.sensors == [0]
    items = list(rec)
    assert len(items) == len(nominal.frames) == len(rec)
    from_rest = dexitac.Sensor.from_rest(nominal.rest)
    replayed = rec.sensor(0)
    found = 0
    for item, frame in zip(items, nominal.frames):
        r = item.recorded
        assert r is not None
        for obs in (from_rest.process(frame), replayed.process(item.frame)):
            assert (obs.contact is not None) == r.found
            if r.found:
                assert obs.contact.centre_work_px == r.centre_work_px  # exact
                assert obs.contact.centre_mm == r.centre_mm
                assert obs.contact.area_mm2 == r.area_mm2
                assert obs.contact.source == r.source
            assert obs.n_markers == r.n_markers
        found += r.found
    assert found >= len(items) // 2
    assert len(rec.rest_frames(0)) >= 1
    assert rec.rest_frames(0)[0].dtype == np.uint8


def test_tune_matches_sensor_tune(nominal, cli, tmp_path):
    sensor = dexitac.Sensor.from_rest(nominal.rest)
    pins = len(sensor.rest_markers_px)
    out = tmp_path / "tuned.toml"
    p = run_cli(cli, "sensor", "tune", "--rest", nominal.rest_path, "--pins", pins, "--out", out,
                ok_codes=(0, 1))
    r = sensor.tune(pins=pins)
    assert r.exact == (p.returncode == 0)
    assert r.holes is False  # an untouched synthetic rest
    settings = lambda text: [l for l in text.splitlines() if not l.startswith("#")]  # noqa: E731
    assert settings(r.config_toml) == settings(out.read_text())
    assert settings(dexitac.tune(nominal.rest, pins).config_toml) == settings(r.config_toml)
    # The tuned config is a config.
    assert dexitac.Sensor.from_rest(nominal.rest, config=r.config_toml).rest_markers_px.shape[1] == 2


def test_health_matches_sensor_health(nominal, cli, tmp_path):
    sensor = dexitac.Sensor.from_rest(nominal.rest)
    # No-contact frames: the rest frame itself, twice.
    same = [nominal.rest, nominal.rest.copy()]
    paths = []
    for k, img in enumerate(same):
        paths.append(tmp_path / f"now{k}.png")
        write_png(paths[-1], img)
    p = run_cli(cli, "sensor", "health", "--rest", nominal.rest_path, *paths, ok_codes=(0, 1, 2))
    report = sensor.health(same)
    assert report.verdict == {0: "pass", 1: "warn", 2: "fail"}[p.returncode]
    lines = {l.split(":")[0].strip(): l for l in p.stdout.splitlines() if ":" in l}
    assert lines["rest frame"].startswith(f"rest frame: {report.rest_markers} markers")
    for name in ("missing", "merged", "extra", "damaged", "flickering"):
        assert int(lines[name].split(":")[1].split()[0]) == len(getattr(report, f"{name}_px")), name
    assert f"{100 * report.coverage:.1f} %" in lines["coverage"]
    # A frame with a contact is not a healthy no-contact frame.
    pressed = next(f for f in nominal.frames if sensor.process(f).contact is not None)
    assert sensor.health([pressed]).coverage < report.coverage


def write_png(path: Path, img: np.ndarray) -> None:
    """8-bit grey or RGB PNG, no filter (zlib from the standard library)."""
    import struct
    import zlib

    h, w = img.shape[:2]
    colour = 0 if img.ndim == 2 else 2
    raw = b"".join(b"\x00" + img[y].tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, colour, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
