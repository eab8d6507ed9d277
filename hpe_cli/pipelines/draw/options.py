"""``hpe draw``'s settings: one frozen object built by the click command and by the Python API alike."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ...errors import HpeError
from ..renamed import take_renamed

#: ``--style``: three axis lines (Hopenet's ``draw_axis``) or the pose cube
STYLES = ("axes", "cube")
#: ``--columns``: which label columns are read
USES = ("auto", "angles", "matrix")
#: ``--tdy-origin``: where ``tdy`` is measured from
TDY_ORIGINS = ("auto", "top", "bottom")


def _check_int(name, value, lo, hi=None, optional=True):
    if value is None and optional:
        return
    ok = isinstance(value, int) and not isinstance(value, bool) and value >= lo and (hi is None or value <= hi)
    if not ok:
        want = f"an integer in [{lo}, {hi}]" if hi is not None else f"an integer >= {lo}"
        raise HpeError(f"{name}: expected {want}, got {value!r}")


def _check_choice(name, value, choices):
    if value not in choices:
        raise HpeError(f"{name}: expected one of {', '.join(choices)}, got {value!r}")


@dataclass(frozen=True)
class DrawOptions:
    """Everything ``hpe draw`` is told besides its input and output folder.

    Attributes
    ----------
    images : str or Path, optional
        Folder the ``image`` column is relative to (default: the input's folder; a ``.mat`` folder itself).
    system : str, path or RotationSystem, optional
        The labels' system when the file names none, and the system of the captions.
    style : {"axes", "cube"}
        Three axis lines or the pose cube.
    canvas : (int, int), optional
        Draw on blank canvases of this width and height (pixels) instead of reading images.
    radians : bool
        Angle columns in radians (default degrees).
    use : {"auto", "angles", "matrix"}
        Which label columns to read.
    length : float, optional
        Line length in pixels for every face, > 0 (overrides ``bbox_h / 2``, ``size`` and ``scale``).
    thickness : int, optional
        Line thickness in pixels, 1..50 (default: from the length).
    tdy_origin : {"auto", "top", "bottom"}
        ``tdy`` measured from the image top or from the bottom row (300W-LP Pose_Para); auto: bottom for
        ``.mat`` input or tables with ``tdz`` and ``scale``.
    annotate : bool
        Write the angles above each face.
    grid : bool
        Write contact sheets instead of images.
    grid_cols : int
        Tiles per row of a contact sheet, 1..64 (a sheet holds ``grid_cols`` x ``grid_cols`` tiles).
    tile : int
        Tile size in pixels, 32..2048.
    limit : int, optional
        Draw at most this many images (>= 1).
    worst : int, optional
        With ``hpe evaluate -o`` output: draw only the ``worst`` rows (>= 1) with the largest ``sort_by``.
    sort_by : str, optional
        With ``hpe evaluate -o`` output: the error column to rank rows by (default ``geodesic``).
    rejects : str or Path, optional
        Rejects file; without it any rejected row is an error.
    strict : bool
        Any rejected row is an error even with ``rejects``.
    overwrite : bool
        Replace existing outputs.
    threads : int, optional
        Threads that draw and write the pictures, >= 1; OpenCV's and pyarrow's pools are limited to the same
        number for the run (default: one per core, at most 8). The output is the same whatever the number.
    rejects_path : str or Path, optional
        Deprecated spelling of ``rejects`` (a ``DeprecationWarning``).

    Raises
    ------
    HpeError
        A setting out of its range: "expected X, got Y".
    """

    images: str | Path | None = None
    system: object = None
    style: str = "axes"
    canvas: tuple | None = None
    radians: bool = False
    use: str = "auto"
    length: float | None = None
    thickness: int | None = None
    tdy_origin: str = "auto"
    annotate: bool = False
    grid: bool = False
    grid_cols: int = 6
    tile: int = 256
    limit: int | None = None
    worst: int | None = None
    sort_by: str | None = None
    rejects: str | Path | None = None
    strict: bool = False
    overwrite: bool = False
    threads: int | None = None
    rejects_path: str | Path | None = None

    def __post_init__(self):
        take_renamed(self, "rejects_path", "rejects")
        _check_choice("style", self.style, STYLES)
        _check_choice("use", self.use, USES)
        _check_choice("tdy_origin", self.tdy_origin, TDY_ORIGINS)
        _check_int("thickness", self.thickness, 1, 50)
        _check_int("grid_cols", self.grid_cols, 1, 64, optional=False)
        _check_int("tile", self.tile, 32, 2048, optional=False)
        _check_int("limit", self.limit, 1)
        _check_int("worst", self.worst, 1)
        _check_int("threads", self.threads, 1)
        if self.length is not None and not (isinstance(self.length, (int, float)) and self.length > 0):
            raise HpeError(f"length: expected a number of pixels > 0, got {self.length!r}")
        if self.canvas is not None:
            size = tuple(self.canvas)
            if len(size) != 2:
                raise HpeError(f"canvas: expected (width, height), got {self.canvas!r}")
            for v in size:
                _check_int("canvas", v, 1)
            object.__setattr__(self, "canvas", size)
