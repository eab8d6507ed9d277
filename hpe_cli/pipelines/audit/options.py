"""The settings of one ``hpe audit`` run, validated once (built by ``cli/audit.py`` and ``hpe_cli.api`` alike)."""

from __future__ import annotations

from dataclasses import dataclass

from ...errors import HpeError
from ...io.table_source import DEFAULT_BATCH
from ...metrics import consistency as mc
from ...metrics.sketch import EXACT_CAP
from ...rotation.audit import NEAR_GIMBAL_DEG
from ...rotation.decoders import DECODERS
from ..renamed import take_renamed

#: default threshold of the time check of ``--consistency``, degrees per frame
MAX_JUMP_DEG = 5.0
#: neighbours further apart than this many frames are not compared
MAX_GAP_FRAMES = 10


@dataclass
class Settings:
    """Thresholds of the ``--consistency`` checks (:mod:`hpe_cli.pipelines.audit.consistency`)."""

    calibration: str | None = None
    max_jump_deg: float = MAX_JUMP_DEG
    max_gap: int = MAX_GAP_FRAMES
    suspect_score: float = mc.SUSPECT_SCORE
    worst: int = 20
    drawn: int = 12
    #: rows whose statistics are kept exactly; beyond, fixed-resolution histograms (flat memory)
    exact_rows: int = EXACT_CAP
    #: a Parquet table sorted by (sequence, frame) runs the views and time checks as its rows stream
    stream_groups: bool = True


#: ``use`` values: the labels' columns (``auto``: the system's own, else angles, else r00..r22)
USES = ("auto", "angles", "matrix")


@dataclass(frozen=True)
class AuditOptions:
    """What to check and what to write.

    Attributes
    ----------
    report : str or path, optional
        The JSON report (``--json``); ``"-"`` prints it through the run's ``echo``.
    plots : str or path, optional
        Folder of histograms, the coverage map and ``index.html`` (``--plots``).
    output : str or path, optional
        The table with one boolean column per check and ``flagged`` (``-o``).
    only_flagged : bool
        With ``output``: only the flagged rows.
    near_tol_deg : float
        ``near_gimbal`` tolerance, degrees from the lock, in [0, 90] (``--gimbal-tol``).
    radians : bool
        Angle labels are in radians.
    use : {"auto", "angles", "matrix"}
        Which label columns to audit (``--columns``).
    keys : tuple of str
        Columns that identify a sample for ``duplicates`` (``--key``); empty: any of
        :data:`~hpe_cli.pipelines.audit.duplicates.ID_COLUMNS` present.
    n_examples : int
        Example rows per check in the report, >= 0 (``--examples``).
    overwrite : bool
        Replace existing outputs.
    batch_size : int
        Rows per record batch, >= 1.
    decoder : str, optional
        A published decoder whose printed angles are compared with each rotation (``--decoder``).
    threads : int, optional
        Worker threads checking batches, >= 1 (``--threads``); None: one per core
        (:func:`hpe_cli.pipelines.pools.default_threads`). The results do not depend on it.
    images : str or path, optional
        Folder of the images for the pictures of ``plots``.
    rejects : str or path, optional
        File for the rows the reader cannot parse (``--rejects``); without it such a row is an error.
    strict : bool
        With ``rejects``: any such row is still an error and nothing is written.
    consistency : Settings, optional
        ``--consistency`` and its thresholds (True: the defaults).
    suspects : str or path, optional
        With ``consistency``: the suspects' key list (``--suspects``).
    strict_rejects : bool, optional
        Deprecated spelling of ``strict`` (a ``DeprecationWarning``).
    workers : int, optional
        Deprecated spelling of ``threads`` (a ``DeprecationWarning``; ``audit_file(workers=)`` was released).
    """

    report: object = None
    plots: object = None
    output: object = None
    only_flagged: bool = False
    near_tol_deg: float = NEAR_GIMBAL_DEG
    radians: bool = False
    use: str = "auto"
    keys: tuple = ()
    n_examples: int = 5
    overwrite: bool = False
    batch_size: int = DEFAULT_BATCH
    decoder: str | None = None
    threads: int | None = None
    images: object = None
    rejects: object = None
    strict: bool = False
    consistency: Settings | None = None
    suspects: object = None
    strict_rejects: bool | None = None
    workers: int | None = None

    def __post_init__(self):
        take_renamed(self, "strict_rejects", "strict")
        take_renamed(self, "workers", "threads")
        object.__setattr__(self, "keys", tuple(self.keys or ()))
        if self.consistency is True:
            object.__setattr__(self, "consistency", Settings())
        elif self.consistency is False:
            object.__setattr__(self, "consistency", None)
        checks = [
            (0 <= self.near_tol_deg <= 90, "near_tol_deg in [0, 90]", self.near_tol_deg),
            (self.use in USES, f"use among {', '.join(USES)}", self.use),
            (isinstance(self.n_examples, int) and self.n_examples >= 0, "n_examples >= 0", self.n_examples),
            (isinstance(self.batch_size, int) and self.batch_size >= 1, "batch_size >= 1", self.batch_size),
            (self.threads is None or int(self.threads) >= 1, "threads >= 1", self.threads),
            (self.decoder is None or self.decoder in DECODERS, f"decoder among {', '.join(DECODERS)}", self.decoder),
            (
                self.consistency is None or isinstance(self.consistency, Settings),
                "consistency Settings",
                self.consistency,
            ),
        ]
        for ok, expected, got in checks:
            if not ok:
                raise HpeError(f"audit options: expected {expected}, got {got!r}")
