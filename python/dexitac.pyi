"""The DexiTac tactile pipeline: numpy frames in, contacts out.

Pixel coordinates named ``*_px`` are in the pixels of the arrays you pass
(input px, as in the CSV of ``dexitac analyze``); ``*_work_px`` are in the
working frame (after the config's crop and rescale; what recordings store).
Bad arrays, configs and frames raise ``ValueError``; unreadable files raise
``OSError``.
"""

import os
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

Frame = npt.NDArray[np.uint8]
"""uint8, C-contiguous, (H, W) grey or (H, W, 3) RGB / (H, W, 4) RGBA (made grey
by the config's ``[frame] grey``: the brightest channel by default, or ``"luma"``)."""

Config = Union[None, str, "os.PathLike[str]", Mapping[str, Any]]
"""None (the paper's parameters), TOML text (str), a TOML file (pathlib.Path)
or a dict of the same tables, e.g. ``{"density": {"kernel_width_px": 12}}``."""

class Contact:
    """A contact: where and how large."""

    @property
    def centre_px(self) -> Tuple[float, float]:
        """Contact centre (x, y), input px (``cx``, ``cy`` of ``dexitac analyze``)."""
    @property
    def centre_work_px(self) -> Tuple[float, float]:
        """Contact centre (x, y), working px."""
    @property
    def centre_mm(self) -> Tuple[float, float]:
        """Contact centre (x, y), mm from the working frame's centre."""
    @property
    def area_mm2(self) -> float:
        """Contact area, mm^2."""
    @property
    def source(self) -> str:
        """How the centre was found: "density", "density+tracking" or "tracking"."""

class StageTimes:
    """Wall-clock time per stage of one frame, ms, measured in Rust."""

    @property
    def prepare_ms(self) -> float:
        """Grey, crop and rescale."""
    @property
    def detect_ms(self) -> float:
        """Preparation and marker detection (``t_detect_ms``)."""
    @property
    def kde_ms(self) -> float:
        """Tracking and kernel density (``t_kde_ms``)."""
    @property
    def segment_ms(self) -> float:
        """Region, centre and contact (``t_segment_ms``)."""
    @property
    def total_ms(self) -> float:
        """The whole frame, preparation included (``t_total_ms``)."""

class Observation:
    """The result of one frame."""

    @property
    def contact(self) -> Optional[Contact]:
        """The contact, or None."""
    @property
    def markers_px(self) -> npt.NDArray[np.float64]:
        """Detected marker centres, (N, 2), input px."""
    @property
    def displacements_px(self) -> npt.NDArray[np.float64]:
        """Per rest marker (``Sensor.rest_markers_px`` order), (dx, dy), (M, 2), input px; NaN where lost.

        In a frame blurrier than the rest, the blur's own shift of each centroid is taken off, and markers
        it shifts by 1 px or more are NaN (a dome's crowded outer rings)."""
    @property
    def n_markers(self) -> int:
        """Number of detected markers."""
    @property
    def skipped(self) -> bool:
        """No marker moved strongly: the density stages were skipped."""
    @property
    def blank(self) -> bool:
        """Fewer than half the rest markers were found: no contact reported."""
    @property
    def times(self) -> StageTimes:
        """Per-stage times."""
    @property
    def density(self) -> Optional[npt.NDArray[np.float32]]:
        """With ``process(frame, density=True)``: the density grid, (rows, cols), markers per mm^2."""

class TuneResult:
    """What ``Sensor.tune`` / ``dexitac.tune`` found."""

    @property
    def config_toml(self) -> str:
        """The sensor config with the tuned ``[markers]``, TOML text (pass as ``config=``)."""
    @property
    def found(self) -> int:
        """Markers found with the tuned setting."""
    @property
    def pins(self) -> int:
        """The pin count asked for."""
    @property
    def exact(self) -> bool:
        """True when exactly ``pins`` markers are found."""
    @property
    def ratio_range(self) -> Optional[Tuple[float, float]]:
        """Strength thresholds around the chosen one that also find ``pins``."""
    @property
    def tried(self) -> int:
        """Settings tried."""
    @property
    def holes(self) -> bool:
        """The rest's marker lattice has holes with the tuned setting (a pressed rest, or the
        median image of taps): the count is not to be trusted."""
    @property
    def summary(self) -> str:
        """One line, as ``dexitac sensor tune`` logs it."""

class HealthReport:
    """What ``Sensor.health`` found. Positions are (N, 2) float64, input px."""

    @property
    def verdict(self) -> str:
        """"pass", "warn" or "fail"."""
    @property
    def reasons(self) -> list[str]:
        """Why the verdict is not a pass."""
    @property
    def rest_markers(self) -> int: ...
    @property
    def pitch_work_px(self) -> float: ...
    @property
    def frames(self) -> int: ...
    @property
    def missing_px(self) -> npt.NDArray[np.float64]: ...
    @property
    def flickering_px(self) -> npt.NDArray[np.float64]: ...
    @property
    def merged_px(self) -> npt.NDArray[np.float64]: ...
    @property
    def extra_px(self) -> npt.NDArray[np.float64]: ...
    @property
    def damaged_px(self) -> npt.NDArray[np.float64]: ...
    @property
    def coverage(self) -> float:
        """Worst frame's fraction (0..1) of the sensing area at or above the contact threshold."""
    @property
    def jitter_work_px(self) -> Optional[Tuple[float, float]]:
        """Median and largest per-marker jitter, working px (None with fewer than two frames)."""

class Sensor:
    """A calibrated tactile sensor (one fingertip)."""

    @staticmethod
    def from_rest(rest: Union[Frame, Sequence[Frame]], config: Config = None) -> "Sensor":
        """Calibrates on one rest frame (no contact) or several, as ``dexitac analyze --rest``.

        Warns (``UserWarning``) when the rest's marker lattice has holes (a pressed rest, or the
        median image of taps)."""
    @staticmethod
    def from_rest_frames(frames: Sequence[Frame], config: Config = None) -> "Sensor":
        """Estimates the rest from the frames themselves, as ``dexitac analyze --rest-from-frames``."""
    def process(self, frame: Frame, density: bool = False) -> Observation:
        """Runs the pipeline on one frame (GIL released meanwhile)."""
    def tune(self, pins: int) -> TuneResult:
        """Tunes the marker detector to ``pins`` markers on the rest frame (``dexitac sensor tune``)."""
    def health(
        self,
        frames: Union[None, Frame, Sequence[Frame]] = None,
        pins: Optional[int] = None,
        min_coverage_pct: float = 98.0,
        max_jitter_px: float = 0.5,
    ) -> HealthReport:
        """Checks the skin on no-contact frames against the rest frame (``dexitac sensor health``)."""
    @property
    def rest_markers_px(self) -> npt.NDArray[np.float64]:
        """Rest marker positions, (M, 2), input px."""
    @property
    def pitch_work_px(self) -> float:
        """Median nearest-neighbour distance of the rest markers, working px."""
    @property
    def input_size_px(self) -> Tuple[int, int]:
        """Input frame size (width, height), px."""
    @property
    def work_size_px(self) -> Tuple[int, int]:
        """Working frame size (width, height), px."""
    @property
    def mm_per_px(self) -> float:
        """Sensor scale, mm per working px."""
    @property
    def density_step_px(self) -> int:
        """Spacing of the density grid, working px."""
    @property
    def rest_density(self) -> npt.NDArray[np.float32]:
        """The rest density on the density grid, (rows, cols), markers per mm^2."""
    @property
    def config_toml(self) -> str:
        """The sensor config in use, TOML text (every field)."""

class Shift:
    """Frame-to-frame and from-anchor shift of the contact centre, mm."""

    @property
    def frame_to_frame_mm(self) -> Optional[float]:
        """Against the previous frame's centre (None without both)."""
    @property
    def from_anchor_mm(self) -> Optional[float]:
        """Against the held anchor (None without an anchor or a contact)."""

class ShiftTracker:
    """Follows the contact centre over frames (paper Eq. 3), in mm.

    ``dexitac analyze`` writes ``shift_mm`` and ``shift_from_anchor_mm``, holding
    the first contact as the anchor.
    """

    def __init__(self, mm_per_px: float) -> None:
        """A tracker for a sensor of ``mm_per_px`` mm per working px (``Sensor.mm_per_px``)."""
    def update(self, frame: Union[Observation, Contact, None]) -> Shift:
        """Feeds the next frame's contact (None: no contact); returns the shifts."""
    def hold_anchor(self) -> bool:
        """Holds the latest centre as the anchor; False when the latest frame had no contact."""
    def release_anchor(self) -> None:
        """Drops the anchor."""

class RecordedContact:
    """A recorded pipeline result (``dexitac.Contact`` message)."""

    @property
    def found(self) -> bool: ...
    @property
    def centre_work_px(self) -> Optional[Tuple[float, float]]: ...
    @property
    def centre_mm(self) -> Optional[Tuple[float, float]]: ...
    @property
    def area_mm2(self) -> Optional[float]: ...
    @property
    def source(self) -> Optional[str]: ...
    @property
    def n_markers(self) -> int: ...
    @property
    def pipeline_ms(self) -> float: ...

class RecordedFrame:
    """One recorded frame and the observation recorded with it."""

    @property
    def sensor(self) -> int: ...
    @property
    def t_ms(self) -> int: ...
    @property
    def frame(self) -> npt.NDArray[np.uint8]:
        """The working frame, (H, W)."""
    @property
    def recorded(self) -> Optional[RecordedContact]: ...

class Recording:
    """An MCAP recording; iterate it for its frames in file order."""

    @property
    def path(self) -> Path: ...
    @property
    def sensors(self) -> list[int]: ...
    @property
    def sensor_config_toml(self) -> Optional[str]: ...
    @property
    def source(self) -> Optional[str]: ...
    @property
    def description(self) -> Optional[str]: ...
    @property
    def damage(self) -> Optional[str]: ...
    def rest_frames(self, sensor: int) -> list[npt.NDArray[np.uint8]]:
        """The rest frames ``sensor`` was calibrated on (working frames)."""
    def sensor(self, sensor: int = 0, config: Config = None, rest_frames: int = 1) -> Sensor:
        """A Sensor calibrated as ``dexitac replay`` calibrates it."""
    def __len__(self) -> int: ...
    def __getitem__(self, index: int) -> RecordedFrame: ...
    def __iter__(self) -> Iterator[RecordedFrame]: ...

def read_recording(path: Union[str, "os.PathLike[str]"], recover: bool = False) -> Recording:
    """Reads an MCAP recording (``dexitac record``, ``sim/run --record --record-frames``)."""

def read_image(path: Union[str, "os.PathLike[str]"]) -> npt.NDArray[np.uint8]:
    """Reads a PNG/JPEG as ``dexitac analyze`` decodes it: (H, W), (H, W, 3) or (H, W, 4) uint8."""

def tune(rest: Frame, pins: int, config: Config = None) -> TuneResult:
    """Tunes the marker detector on a rest frame before any Sensor exists."""
