"""The settings of ``hpe relabel-panoptic`` and ``hpe relabel-agora``, one frozen object per command, validated
once; the click modules and the Python API build them alike."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...datasets.agora import AGORA_SIZE
from ...rotation import get_system
from ...rotation.systems import canonical_system
from .agora import DEFAULT_MAX_OCCLUSION
from .agora import DEFAULT_MAX_RMSE as AGORA_MAX_RMSE
from .agora import Config as AgoraConfig
from .core import DEFAULT_MAX_RMSE
from .plan import Config, parse_frames

#: what ``--format`` writes: a Parquet/CSV table, DirectMHP's COCO JSON or WHENet's annotation.txt lines
FORMATS = ("table", "coco", "whenet")


class FormatSystemError(ValueError):
    """``--format coco/whenet`` with a ``--system`` other than whenet (a usage error on the command line)."""


def _label_system(fmt: str, system, who: str):
    """The RotationSystem of the labels: ``system`` (resolved once), by default whenet for the text formats
    (they store whenet angles) and 300w_lp for tables."""
    if fmt not in FORMATS:
        raise ValueError(f"expected --format {', '.join(FORMATS[:-1])} or {FORMATS[-1]}, got {fmt!r}")
    if system is None and fmt != "table":
        system = "whenet"  # the text formats' own system
    system = canonical_system() if system is None else get_system(system)
    if fmt != "table" and system.name != "whenet":
        raise FormatSystemError(
            f"--format {fmt} stores {who} angles, which are in the whenet system; "
            f"got --system {system.name} (use --format table for other systems)"
        )
    return system


def _check_choice(name: str, value, choices) -> None:
    if value not in choices:
        raise ValueError(f"expected {name} {' or '.join(map(str, choices))}, got {value!r}")


def _check_at_least_one(name: str, value) -> None:
    if not isinstance(value, int) or value < 1:
        raise ValueError(f"expected {name} an integer >= 1, got {value!r}")


@dataclass(frozen=True)
class RelabelPanopticOptions:
    """The settings of ``hpe relabel-panoptic`` (see its ``--help``; names as the options').

    ``system`` is a :class:`~hpe_cli.rotation.RotationSystem` or a name, resolved once (default: whenet for
    ``fmt`` coco/whenet, else 300w_lp); ``frames`` is ``(A, B)`` or the text ``"A:B"``; ``max_rmse`` in cm
    (None: :data:`~.core.DEFAULT_MAX_RMSE`, ``inf``: no gate); ``min_change`` in degrees.
    """

    system: object = None
    fmt: str = "table"
    preset: str = "whenet"
    calibration: object = None
    cameras: str = "hd"
    every: int = 1
    frames: object = (None, None)
    min_change: float | None = None
    all_views: bool = False
    frame: str = "camera"
    landmarks: bool = True
    max_rmse: float | None = None
    legacy: bool = False
    workers: int = 1
    scheduler: str | None = None
    resume: bool = False
    rejects: object = None
    strict: bool = False
    overwrite: bool = False

    def __post_init__(self):
        object.__setattr__(self, "system", _label_system(self.fmt, self.system, "WHENet/DirectMHP"))
        if self.frames is None or isinstance(self.frames, str):
            object.__setattr__(self, "frames", parse_frames(self.frames))
        object.__setattr__(self, "frames", tuple(self.frames))
        # numbers as the command line gives them (floats), so the metadata is the same bytes from the API
        object.__setattr__(self, "max_rmse", DEFAULT_MAX_RMSE if self.max_rmse is None else float(self.max_rmse))
        if self.min_change is not None:
            object.__setattr__(self, "min_change", float(self.min_change))
        _check_choice("preset", self.preset, ("whenet", "directmhp"))
        _check_choice("frame", self.frame, ("camera", "crop"))
        _check_at_least_one("every", self.every)
        _check_at_least_one("workers", self.workers)
        if self.min_change is not None and not 0 < self.min_change <= 180:
            raise ValueError(f"expected min_change in (0, 180] degrees, got {self.min_change!r}")

    @property
    def uses_parts(self) -> bool:
        """Whether the units run elsewhere and write part files (workers, a scheduler or ``resume``)."""
        return self.workers > 1 or self.scheduler is not None or self.resume

    def config(self) -> Config:
        """What each unit computes (everything but I/O; small and picklable)."""
        return Config(
            system=self.system,
            preset=self.preset,
            max_rmse=self.max_rmse,
            legacy=self.legacy,
            landmarks=self.landmarks,
            frame=self.frame,
            all_views=self.all_views,
            min_change=self.min_change,
        )


@dataclass(frozen=True)
class RelabelAgoraOptions:
    """The settings of ``hpe relabel-agora`` (see its ``--help``; names as the options').

    ``system`` as for :class:`RelabelPanopticOptions`; ``image_size`` ``(W, H)`` pixels; ``max_rmse`` in
    metres (None: :data:`~.agora.DEFAULT_MAX_RMSE`); ``max_occlusion`` in percent; ``threads`` (>= 1, None:
    one per core, at most 8) the dataframes read and fitted side by side, and the size of OpenCV's and pyarrow's
    pools for the run (the output is the same whatever the number).
    """

    system: object = None
    fmt: str = "table"
    image_size: tuple = AGORA_SIZE
    preset: str = "directmhp"
    max_rmse: float | None = None
    max_occlusion: float = DEFAULT_MAX_OCCLUSION
    legacy: bool = False
    frame: str = "camera"
    trust_pickle: bool = False
    rejects: object = None
    strict: bool = False
    overwrite: bool = False
    threads: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "system", _label_system(self.fmt, self.system, "DirectMHP/WHENet"))
        t = self.threads
        if t is not None and (not isinstance(t, int) or isinstance(t, bool) or t < 1):
            raise ValueError(f"expected threads an integer >= 1 (or None: one per core), got {t!r}")
        object.__setattr__(self, "max_rmse", AGORA_MAX_RMSE if self.max_rmse is None else float(self.max_rmse))
        object.__setattr__(self, "max_occlusion", float(self.max_occlusion))
        object.__setattr__(self, "image_size", tuple(int(v) for v in self.image_size))
        _check_choice("preset", self.preset, ("whenet", "directmhp"))
        _check_choice("frame", self.frame, ("camera", "crop"))
        if len(self.image_size) != 2 or min(self.image_size) <= 0:
            raise ValueError(f"expected image_size (W, H) in pixels, got {self.image_size!r}")
        occ = self.max_occlusion
        if math.isnan(occ) or occ < 0:
            raise ValueError(f"expected max_occlusion a number >= 0 or inf, got {occ}")

    def config(self) -> AgoraConfig:
        """What to compute for each person (everything but I/O)."""
        return AgoraConfig(
            system=self.system,
            image_size=tuple(self.image_size),
            max_rmse=self.max_rmse,
            max_occlusion=self.max_occlusion,
            legacy=self.legacy,
            preset=self.preset,
            frame=self.frame,
            trust_pickle=self.trust_pickle,
        )
