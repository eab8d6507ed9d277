"""``hpe evaluate``'s settings: one frozen object, validated once, built by the click command and the Python API."""

from __future__ import annotations

from dataclasses import dataclass

from ...errors import HpeError
from ...io.table_source import DEFAULT_BATCH
from ...metrics.evaluate import check_protocols

#: ``align`` values: no alignment, or the chordal mean offset removed from every prediction
ALIGNS = ("none", "mean")
#: ``join_mode`` values: pair rows by key columns, or by position (equal row counts)
JOIN_MODES = ("key", "order")
#: ``join_engine`` values for files in different orders: the external hash join, or both sides whole in memory
JOIN_ENGINES = ("spill", "memory")


def _one_of(name: str, value, allowed) -> None:
    if value not in allowed:
        raise HpeError(f"evaluate: expected {name} among {', '.join(allowed)}, got {value!r}")


def _at_least(name: str, value, low) -> None:
    if value is not None and not value >= low:
        raise HpeError(f"evaluate: expected {name} >= {low}, got {value!r}")


@dataclass(frozen=True)
class EvaluateOptions:
    """The settings of one ``hpe evaluate`` run (every field as the command's option of the same meaning).

    Attributes
    ----------
    pred_system, gt_system : str, path or RotationSystem, optional
        Each side's system (``--pred-system``, ``--gt-system``): for files that name none, and the system the
        report is in; a file's own system that disagrees is a usage error.
    output, report, plots, rejects, html : str or Path, optional
        ``-o`` per-row table, ``--json`` report (``"-"``: stdout), ``--plots`` folder, ``--rejects`` file,
        ``--report`` HTML page.
    keys : tuple of str
        ``--key`` columns (empty: ``image``, else ``file``).
    protocols : tuple of str, optional
        ``--protocol`` names (None: every protocol); checked against the protocol table.
    align : {"none", "mean"}
        ``--align``.
    by : str, optional
        ``--by`` column.
    yaw_bins : float, optional
        ``--yaw-bins`` width in degrees, > 0.
    use_pred, use_gt : str
        ``--pred-columns``, ``--gt-columns`` (``"auto"``, ``"angles"``, ``"matrix"``).
    radians, overwrite, strict, orthonormalize : bool
        As the options of those names.
    batch_size : int
        Rows per record batch, >= 1 (default: the CLI's ``--batch-size``, :data:`hpe_cli.io.table_source.DEFAULT_BATCH`).
    join_mode : {"key", "order"}
        ``--join``.
    worst : int
        Rows of the page's worst table, >= 0.
    images : str or Path, optional
        ``--images`` folder of the page's pictures.
    join_engine : {"spill", "memory"}
        Files in different orders: the external hash join (partitions of about ``partition_rows`` rows on
        disk), or both sides whole in memory (the reference the partitioned join is tested against).
    partition_rows : int, optional
        Rows per side and partition of the external join, >= 1 (default
        :data:`hpe_cli.pipelines.evaluate.spill.PARTITION_ROWS`).
    threads : int, optional
        ``--threads``, >= 1 (default: one per core, at most 8).
    """

    pred_system: object = None
    gt_system: object = None
    output: object = None
    keys: tuple = ()
    protocols: tuple | None = None
    align: str = "none"
    by: str | None = None
    yaw_bins: float | None = None
    report: object = None
    plots: object = None
    rejects: object = None
    html: object = None
    use_pred: str = "auto"
    use_gt: str = "auto"
    radians: bool = False
    overwrite: bool = False
    strict: bool = False
    batch_size: int = DEFAULT_BATCH
    join_mode: str = "key"
    orthonormalize: bool = False
    worst: int = 12
    images: object = None
    join_engine: str = "spill"
    partition_rows: int | None = None
    threads: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "keys", tuple(self.keys or ()))
        try:
            protocols = check_protocols(list(self.protocols) if self.protocols else None)
        except ValueError as exc:
            raise HpeError(str(exc)) from None
        object.__setattr__(self, "protocols", tuple(protocols))
        _one_of("align", self.align, ALIGNS)
        _one_of("join_mode", self.join_mode, JOIN_MODES)
        _one_of("join_engine", self.join_engine, JOIN_ENGINES)
        _at_least("batch_size", self.batch_size, 1)
        _at_least("worst", self.worst, 0)
        _at_least("partition_rows", self.partition_rows, 1)
        _at_least("threads", self.threads, 1)
        if self.yaw_bins is not None and not self.yaw_bins > 0:
            raise HpeError(f"evaluate: expected yaw_bins > 0 (degrees), got {self.yaw_bins!r}")
