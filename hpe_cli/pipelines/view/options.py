"""``hpe view``'s settings: one frozen object built by the click command and by the Python API alike."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ...errors import HpeError

#: ``--columns``: which label columns are read
USES = ("auto", "angles", "matrix")


@dataclass(frozen=True)
class ViewOptions:
    """Everything ``hpe view`` is told besides LABELS, OTHER and the page folder.

    Attributes
    ----------
    images : str or Path, optional
        Folder the ``image`` column is relative to (default: LABELS' folder; a ``.mat`` folder itself).
    system, other_system : str, path or RotationSystem, optional
        Each table's system when its file does not name one (``other_system`` defaults to ``system``);
        the page's angles (degrees) are in LABELS' system.
    also_in : sequence of (str or RotationSystem), optional
        Further systems (names or ``.toml`` files) in which every row's angles are computed too; the page's
        selector makes its angle filters, sort, captions and coverage map use one of them.
    radians : bool
        Angle columns in radians (default degrees).
    use : {"auto", "angles", "matrix"}
        Which label columns to read.
    keys : sequence of str, optional
        Columns pairing OTHER's rows with LABELS' (default: ``image`` or ``file``, plus ``person_id`` when both
        tables have it).
    threads : int, optional
        Threads making the pictures (default: one per core, at most 8); OpenCV's own pool is limited to as
        many. The page is the same whatever the number.
    title : str, optional
        Page title (default: LABELS' file name).
    frames : bool
        Make each image once at most :data:`~hpe_cli.pipelines.view.thumbs.FRAME_SIDE` (960) pixels long for
        the detail view; ``False`` shows the thumbnail there (for datasets of many distinct images).
    rejects : str or Path, optional
        Rejects file; without it any rejected row is an error.
    strict : bool
        Any rejected row is an error even with ``rejects``.
    overwrite : bool
        Replace an earlier page in the folder (its thumbnails are reused).

    Raises
    ------
    HpeError
        A setting out of its range: "expected X, got Y".
    """

    images: str | Path | None = None
    system: object = None
    other_system: object = None
    also_in: tuple | None = None
    radians: bool = False
    use: str = "auto"
    keys: tuple | None = None
    threads: int | None = None
    title: str | None = None
    frames: bool = True
    rejects: str | Path | None = None
    strict: bool = False
    overwrite: bool = False

    def __post_init__(self):
        if self.use not in USES:
            raise HpeError(f"use: expected one of {', '.join(USES)}, got {self.use!r}")
        w = self.threads
        if w is not None and not (isinstance(w, int) and not isinstance(w, bool) and w >= 1):
            raise HpeError(f"threads: expected an integer >= 1 or None, got {w!r}")
        if isinstance(self.keys, str) or (self.keys is not None and not all(isinstance(k, str) for k in self.keys)):
            raise HpeError(f"keys: expected a list of column names, got {self.keys!r}")
        if isinstance(self.also_in, str):
            raise HpeError(f"also_in: expected a list of systems, got {self.also_in!r}")
        if self.keys is not None:
            object.__setattr__(self, "keys", tuple(self.keys))
        if self.also_in is not None:
            object.__setattr__(self, "also_in", tuple(self.also_in))
