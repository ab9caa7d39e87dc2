"""Bad input raises ValueError (arrays, configs, frames) or OSError (files),
never crashes, and leaves the sensor usable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dexitac


@pytest.fixture(scope="module")
def sensor(nominal):
    return dexitac.Sensor.from_rest(nominal.rest)


def bad_frames(good: np.ndarray):
    h, w = good.shape
    return {
        "float64": good.astype(np.float64),
        "uint16": good.astype(np.uint16),
        "int8": good.astype(np.int8),
        "bool": good > 0,
        "1-D": good.ravel(),
        "4-D": good.reshape(1, h, w, 1),
        "2 channels": np.zeros((h, w, 2), np.uint8),
        "5 channels": np.zeros((h, w, 5), np.uint8),
        "strided slice": np.zeros((h, 2 * w), np.uint8)[:, ::2],
        "transposed": np.ascontiguousarray(good.T).T,
        "Fortran order": np.asfortranarray(good),
        "empty": np.zeros((0, 0), np.uint8),
        "empty rows": np.zeros((0, w), np.uint8),
        "wrong size": good[: h // 2].copy(),
        "list": good.tolist(),
        "None": None,
        "str": "frame.png",
        "object array": np.empty((h, w), dtype=object),
    }


@pytest.mark.parametrize("case", list(bad_frames(np.zeros((4, 4), np.uint8)).keys()))
def test_bad_frame_raises_value_error(sensor, nominal, case):
    frame = bad_frames(nominal.frames[0])[case]
    with pytest.raises(ValueError):
        sensor.process(frame)
    # Still works after the error.
    assert sensor.process(nominal.frames[0]).n_markers > 0


@pytest.mark.parametrize("case", ["float64", "1-D", "strided slice", "empty", "list", "None"])
def test_bad_rest_raises_value_error(nominal, case):
    with pytest.raises(ValueError):
        dexitac.Sensor.from_rest(bad_frames(nominal.rest)[case])


def test_read_only_and_views_that_are_contiguous_are_accepted(sensor, nominal):
    frame = nominal.frames[0].copy()
    frame.flags.writeable = False
    a = sensor.process(frame)
    b = sensor.process(np.ascontiguousarray(nominal.frames[0][:, :]))
    c = sensor.process(nominal.frames[0][..., np.newaxis])  # (H, W, 1)
    assert np.array_equal(a.markers_px, b.markers_px)
    assert np.array_equal(a.markers_px, c.markers_px)


def test_blank_and_noise_frames_give_no_contact(sensor, nominal):
    for frame in (np.zeros_like(nominal.rest), np.full_like(nominal.rest, 255),
                  np.random.default_rng(1).integers(0, 256, nominal.rest.shape, dtype=np.uint8)):
        obs = sensor.process(frame)
        assert obs.contact is None


def test_rest_without_markers_raises(nominal):
    with pytest.raises(ValueError, match="calibration"):
        dexitac.Sensor.from_rest(np.zeros_like(nominal.rest))


def test_rest_frames_of_different_sizes_raise(nominal):
    with pytest.raises(ValueError, match="rest"):
        dexitac.Sensor.from_rest([nominal.rest, nominal.rest[:100].copy()])


@pytest.mark.parametrize("config, match", [
    ("[frame]\nfoo = 1\n", "unknown field"),
    ("[frame\n", "TOML"),
    ("sensor.toml", "pathlib.Path"),
    ({"frame": {"mm_per_px": -1.0}}, "mm_per_px"),
    ({"frame": {"mm_per_px": "x"}}, "mm_per_px|invalid"),
    ({"nope": {}}, "unknown field"),
    ({"frame": {"crop_px": [1, 2, object()]}}, "TOML value"),
    ({1: 2}, "keys must be str"),
    (42, "config must be"),
])
def test_bad_config_raises_value_error(nominal, config, match):
    with pytest.raises(ValueError, match=match):
        dexitac.Sensor.from_rest(nominal.rest, config=config)


def test_missing_files_raise_os_error(nominal, tmp_path):
    with pytest.raises(OSError):
        dexitac.Sensor.from_rest(nominal.rest, config=tmp_path / "missing.toml")
    with pytest.raises(OSError):
        dexitac.read_image(tmp_path / "missing.png")
    with pytest.raises(OSError):
        dexitac.read_recording(tmp_path / "missing.mcap")


def test_files_of_the_wrong_kind_raise_value_error(tmp_path):
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image at all")
    with pytest.raises(ValueError):
        dexitac.read_image(junk)
    with pytest.raises(ValueError, match="MCAP"):
        dexitac.read_recording(junk)


def test_tune_and_health_check_their_arguments(sensor, nominal):
    with pytest.raises(ValueError, match="pin count"):
        sensor.tune(pins=2)
    with pytest.raises(ValueError):
        sensor.health([nominal.rest[:10].copy()])
    with pytest.raises(ValueError):
        sensor.health(min_coverage_pct=150.0)
    estimated = dexitac.Sensor.from_rest_frames(nominal.frames)
    with pytest.raises(ValueError, match="from_rest_frames"):
        estimated.tune(pins=100)


def test_observation_fields(sensor, nominal):
    frame = next(f for f in nominal.frames if sensor.process(f).contact is not None)
    obs = sensor.process(frame)
    assert obs.markers_px.dtype == np.float64 and obs.markers_px.shape == (obs.n_markers, 2)
    assert obs.displacements_px.shape == sensor.rest_markers_px.shape
    assert obs.density is None
    c = obs.contact
    x, y = c.centre_px
    assert 0 <= x < 640 and 0 <= y < 480
    assert c.centre_mm == pytest.approx(((x - 319.5) * sensor.mm_per_px, (y - 239.5) * sensor.mm_per_px))
    assert c.area_mm2 > 0 and c.source in ("density", "density+tracking", "tracking")
    t = obs.times
    assert 0 < t.prepare_ms <= t.detect_ms <= t.total_ms
    # The density grid: lower than rest around the contact.
    d = sensor.process(frame, density=True).density
    rest = sensor.rest_density
    assert d.shape == rest.shape and d.dtype == np.float32
    step = sensor.density_step_px
    i, j = int(c.centre_work_px[0] // step), int(c.centre_work_px[1] // step)
    assert d[j, i] < rest[j, i]
    assert "Sensor(" in repr(sensor) and "Observation(" in repr(obs)


def test_damaged_recording_raises_unless_recovered(nominal, cli, tmp_path):
    from conftest import run_cli

    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "0000.png").write_bytes(nominal.rest_path.read_bytes())
    for k, p in enumerate(nominal.frame_paths[:3]):
        (folder / f"{k + 1:04d}.png").write_bytes(p.read_bytes())
    whole = tmp_path / "whole.mcap"
    run_cli(cli, "record", "--out", whole, "--frames", folder, "--max-speed")
    rec = dexitac.read_recording(whole)
    assert rec.damage is None and len(rec) == 3
    assert rec[-1].t_ms == rec[2].t_ms
    with pytest.raises(IndexError):
        rec[3]
    with pytest.raises(ValueError, match="no frames"):
        rec.sensor(5)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size * 2 // 3])
    with pytest.raises(ValueError, match="damaged"):
        dexitac.read_recording(cut)
    assert dexitac.read_recording(cut, recover=True).damage


def test_shift_tracker_checks_its_input(sensor, nominal):
    with pytest.raises(ValueError):
        dexitac.ShiftTracker(0.0)
    t = dexitac.ShiftTracker(sensor.mm_per_px)
    with pytest.raises(ValueError):
        t.update("not a frame")
    assert t.update(None).frame_to_frame_mm is None
    assert not t.hold_anchor()
    obs = next(o for o in map(sensor.process, nominal.frames) if o.contact is not None)
    assert t.update(obs.contact).frame_to_frame_mm is None
    assert t.hold_anchor()
    s = t.update(obs)
    assert s.frame_to_frame_mm == 0.0 and s.from_anchor_mm == 0.0


def test_a_rest_with_a_hole_warns():
    # Bright spots on a 16 px lattice, the middle ones left out (a pressed
    # rest, or the median of taps): a UserWarning, and the sensor works.
    yy, xx = np.mgrid[0:480, 0:640]
    img = np.full((480, 640), 40.0)
    row = 16.0 * np.sqrt(3) / 2
    for j in range(int(480 / row) + 1):
        for i in range(41):
            x, y = i * 16.0 + (8.0 if j % 2 else 0.0), j * row
            if np.hypot(x - 320, y - 240) >= 64:
                img += 150 * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / 8.0)
    rest = np.clip(img, 0, 255).round().astype(np.uint8)
    with pytest.warns(UserWarning, match="holes"):
        s = dexitac.Sensor.from_rest(rest)
    assert s.process(rest) is not None
