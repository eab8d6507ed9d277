"""The Python API (``import hpe_cli as hpe``): thin wrappers over the readers and pipelines the CLI runs.

:mod:`hpe_cli` re-exports every name here lazily (``hpe.read_labels`` imports
this module on first use), so ``import hpe_cli`` stays fast. File-level
functions (:func:`read_labels`, :func:`convert_file`, :func:`audit_file`) call
the same reader, system resolution (:func:`hpe_cli.io.system_meta.resolve_system`),
storage kinds and rejects as ``hpe convert``/``hpe audit``; array functions
call the same kernels.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pyarrow as pa

from .api_arrays import augment_batch, augment_sample, draw_axes, geodesic, landmark_pose  # noqa: F401
from .io.layout import arrow_table
from .io.readers import open_table
from .io.system_meta import file_system, resolve_system
from .io.transaction import ensure_transaction
from .io.writers import system_metadata, write_table
from .metrics.evaluate import evaluate as _evaluate
from .pipelines.audit import AuditOptions, run_audit
from .pipelines.augment import AugmentOptions, run_augment
from .pipelines.biwi import BiwiOptions, run_biwi
from .pipelines.convert import ConvertOptions, run_convert
from .pipelines.draw import DrawOptions, run_draw
from .pipelines.evaluate import EvaluateOptions, run_evaluate
from .pipelines.infer import InferOptions, finish, run_infer
from .pipelines.relabel import RelabelAgoraOptions, RelabelPanopticOptions, run_relabel_agora, run_relabel_panoptic
from .pipelines.view import ViewOptions, run_view
from .rotation import storage as st
from .rotation.audit import audit_angles, audit_matrices
from .rotation.convert import canonical_to_labels
from .rotation.systems import builtin_systems
from .rotation.systems import get_system as _get

STORAGE_KINDS = ("angles", "matrix", "rotvec", "quaternion", "6d")


# ---------------------------------------------------------------------------------------------- systems
def get_system(spec):
    """A rotation system by name, TOML path, or a ``RotationSystem`` returned as is.

    Parameters
    ----------
    spec : str, path or RotationSystem
        A built-in name (see :func:`systems`), a ``.toml`` system file, or a system.

    Returns
    -------
    RotationSystem

    Raises
    ------
    ValueError
        Unknown name or invalid TOML file (``hpe_cli.rotation.SystemError_``).

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> s = hpe.get_system("300w_lp")
    >>> s.name, s.axes, s.sequence
    ('300w_lp', 'xyz', 'intrinsic')
    >>> s.from_angles([[0.0, 90.0, 0.0]]).round(12)[0]
    array([[ 0.,  0., -1.],
           [ 0.,  1.,  0.],
           [ 1.,  0.,  0.]])
    """

    return _get(spec)


def systems() -> dict:
    """Every built-in rotation system, by name.

    Returns
    -------
    dict of str to RotationSystem
        Read once from ``configs/systems/*.toml``; names sorted.

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> "300w_lp" in hpe.systems() and "6drepnet" in hpe.systems()
    True
    >>> hpe.systems()["biwi"].describe()["order"]
    'extrinsic XYZ, active matrix'
    """

    return builtin_systems()


# -------------------------------------------------------------------------------------------- convert
def _storage_to_matrix(values, storage: str, quaternion_order: str, sixd_columns=(0, 1)):
    """Rotation vectors (radians), quaternions or 6-D vectors to matrices (N, 3, 3) (:mod:`hpe_cli.rotation.storage`)."""

    if storage == "rotvec":
        return st.rotvec_to_matrix(values)
    if storage == "quaternion":
        norm = np.linalg.norm(values, axis=-1)
        if not (np.abs(norm - 1.0) <= 1e-3).all():
            row = int(np.flatnonzero(~(np.abs(norm - 1.0) <= 1e-3))[0])
            raise ValueError(f"row {row + 1}: expected a unit quaternion, got norm {norm[row]:.6g}")
        return st.quaternion_to_matrix(values, order=quaternion_order)
    return st.sixd_to_matrix(values, sixd_columns)


def convert(values, src, dst, storage: str | None = None, *, quaternion_order: str | None = None):
    """Express rotations given in system ``src`` as labels of system ``dst``.

    Parameters
    ----------
    values : array_like
        ``angles``: shape (N, 3) or (3,), ``(pitch, yaw, roll)`` in degrees, any real values;
        ``matrix``: shape (N, 3, 3) or (3, 3), ``src``'s stored matrices;
        ``rotvec``: shape (N, 3), rotation vectors of ``src``'s stored matrix, radians;
        ``quaternion``: shape (N, 4), unit quaternions of ``src``'s stored matrix;
        ``6d``: shape (N, 6), two columns of ``src``'s stored matrix (``src.sixd_columns``,
        default columns 0 and 1 as 6DRepNet), re-orthonormalised by Gram-Schmidt.
    src, dst : str, path or RotationSystem
        Source and target systems (see :func:`get_system`).
    storage : {"angles", "matrix", "rotvec", "quaternion", "6d"}, optional
        How ``values`` are given. Default: ``matrix`` for (N, 3, 3), ``quaternion``
        for (N, 4) or (4,), ``6d`` for (N, 6), else ``angles``. Rotation vectors must
        be asked for, and so must a single (3, 3) input (one matrix or three angle rows).
    quaternion_order : {"wxyz", "xyzw"}, optional
        Component order of quaternions (SciPy uses ``xyzw``); default ``src.quaternion_order``
        (``wxyz`` unless the system says otherwise).

    Returns
    -------
    Conversion
        ``primary``/``secondary`` (N, 3) degrees in (-180, 180], ``matrix`` (N, 3, 3)
        ``dst``'s stored matrix, ``gimbal_lock`` (N,) bool, ``roundtrip_err`` (N,),
        ``canonical`` (N, 3, 3). A single input row still gives N = 1.

    Raises
    ------
    ValueError
        Unknown ``storage`` or a shape that does not fit it.

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> c = hpe.convert([10.0, 30.0, -5.0], "300w_lp", "6drepnet")
    >>> c.primary.round(6)
    array([[10., 30., -5.]])
    >>> c.secondary.round(6), c.matrix.shape, c.gimbal_lock
    (array([[-170.,  150.,  175.]]), (1, 3, 3), array([False]))
    >>> hpe.convert([1.0, 0.0, 0.0, 0.0], "300w_lp", "300w_lp", storage="quaternion").primary + 0.0
    array([[0., 0., 0.]])
    """

    source, target = get_system(src), get_system(dst)
    v = np.asarray(values, dtype=np.float64)
    if storage is None:
        if v.shape == (3, 3):
            raise ValueError(
                "a (3, 3) input is three angle rows or one matrix: pass storage='angles' or storage='matrix'"
            )
        storage = (
            "matrix"
            if v.ndim == 3
            else "quaternion"
            if v.shape[-1:] == (4,)
            else "6d"
            if v.shape[-1:] == (6,)
            else "angles"
        )
    if storage not in STORAGE_KINDS:
        raise ValueError(f"expected storage in {', '.join(STORAGE_KINDS)}, got {storage!r}")
    if quaternion_order is None:
        quaternion_order = getattr(source, "quaternion_order", "wxyz")
    if quaternion_order not in ("wxyz", "xyzw"):
        raise ValueError(f"expected quaternion_order 'wxyz' or 'xyzw', got {quaternion_order!r}")
    width = {"angles": (3,), "matrix": (3, 3), "rotvec": (3,), "quaternion": (4,), "6d": (6,)}[storage]
    if v.shape[-len(width) :] != width or v.ndim > len(width) + 1:
        raise ValueError(f"expected {storage} values of shape (N, {', '.join(map(str, width))}), got {v.shape}")
    v = v.reshape((-1,) + width)
    if storage == "angles":
        R = source.from_angles(v)
    elif storage == "matrix":
        R = v
    else:
        R = _storage_to_matrix(v, storage, quaternion_order, getattr(source, "sixd_columns", (0, 1)))
    return canonical_to_labels(source.to_canonical(R), target)


# ----------------------------------------------------------------------------------------------- I/O
class LabelTable(tuple):
    """``(table, system)``: a pandas DataFrame and its RotationSystem (or None). Unpacks as a pair."""

    __slots__ = ()

    def __new__(cls, table, system):
        return super().__new__(cls, (table, system))

    @property
    def table(self):
        return self[0]

    @property
    def system(self):
        return self[1]

    def __repr__(self):
        name = None if self[1] is None else self[1].name
        return f"LabelTable(rows={len(self[0])}, columns={len(self[0].columns)}, system={name!r})"


def read_labels(path, system=None, *, reinterpret_as=None, **reader_options) -> LabelTable:
    """Read a label table and the rotation system its labels are in.

    Parameters
    ----------
    path : str or path
        ``.parquet``/``.csv`` label table, a folder (or file) of 300W-LP/AFLW2000
        ``.mat`` files, or BIWI pose files -- anything ``hpe`` commands read.
    system : str, path or RotationSystem, optional
        Use this system when the file does not name one (CSV files carry no metadata);
        one that disagrees with the file's own is an error, as ``--system`` is.
    reinterpret_as : str, path or RotationSystem, optional
        The file's metadata is wrong: read the labels in this system (``--reinterpret-as``).
    **reader_options
        Passed to :func:`hpe_cli.io.open_table` (e.g. ``batch_size``; ``columns``,
        ``delimiter``, ``header``, ``input_format`` where supported).

    Returns
    -------
    LabelTable
        ``(table, system)``: a pandas DataFrame with one row per label, and the
        system as every ``hpe`` command resolves it
        (:func:`hpe_cli.io.system_meta.resolve_system`): the file's own (Parquet
        ``hpe:system_definition``/``hpe:system``, COCO ``info``, WHENet
        ``annotation.txt``, ``300w_lp`` for ``.mat``, ``biwi`` for BIWI), else
        ``system`` (None when not given). Rows are those ``hpe`` commands read,
        with the same keys (``image`` for ``.mat`` folders and BIWI).

    Raises
    ------
    HpeError
        Missing or unreadable file, or an unreadable row (one line naming it:
        ``FILE: line N``, ``FILE: row N`` or ``FILE``).
    UsageError
        ``system`` disagrees with the file's own system.

    Examples
    --------
    >>> import tempfile, os, hpe_cli as hpe
    >>> d = tempfile.mkdtemp()
    >>> p = hpe.write_labels({"pitch": [1.0], "yaw": [2.0], "roll": [3.0]}, os.path.join(d, "l.parquet"),
    ...                      system="6drepnet")
    >>> table, system = hpe.read_labels(p)
    >>> system.name, table["yaw"].tolist()
    ('6drepnet', [2.0])
    """

    src = open_table(path, **reader_options)
    found = None
    if system is not None or reinterpret_as is not None or file_system(src) is not None:
        found = resolve_system(src, system, default=None, reinterpret=reinterpret_as).system
    table = pa.Table.from_batches(list(src.batches()), schema=src.schema)
    return LabelTable(table.to_pandas(), found)


def convert_file(
    input,
    output,
    target,
    source=None,
    *,
    radians: bool = False,
    rejects=None,
    strict: bool = False,
    overwrite: bool = False,
    decoder=None,
    batch_size: int = 65_536,
    threads: int | None = None,
):
    """``hpe convert`` as a function: the same pipeline (:func:`hpe_cli.pipelines.convert.run_convert`).

    Parameters
    ----------
    input, output : str or path
        Any table ``hpe`` reads; a ``.parquet`` or ``.csv`` to write (atomically).
    target : str, path or RotationSystem
        The system to write (``--to``).
    source : str, path or RotationSystem, optional
        The input's system (``--from``); default: the file's own (an error when it names none).
    radians, rejects, strict, overwrite, decoder, batch_size, threads
        As the command's options (``threads``: ``--threads``, one per core by default).

    Returns
    -------
    ConvertSummary
        ``rows``, ``written``, ``gimbal_lock``, ``max_roundtrip_err``, ``rejects`` (reason -> count),
        ``source`` and ``source_origin`` ("file metadata", "option" or "default").
    """

    options = ConvertOptions(
        radians=radians,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        batch_size=batch_size,
        threads=threads,
        decoder=decoder,
    )
    with ensure_transaction():
        return run_convert(input, output, None if source is None else get_system(source), get_system(target), options)


def audit_file(
    input,
    system=None,
    *,
    report=None,
    output=None,
    rejects=None,
    strict: bool = False,
    overwrite: bool = False,
    **options,
) -> dict:
    """``hpe audit`` as a function: the same pipeline (:func:`hpe_cli.pipelines.audit.run_audit`).

    Returns the JSON report (``rows``, one count per check, ``system``,
    ``system_origin``, ``rejected``, ``examples``...); ``system`` defaults to
    the file's own, else ``300w_lp``. ``options``: ``near_tol_deg``, ``radians``,
    ``use``, ``keys``, ``n_examples``, ``batch_size``, ``decoder``, ``threads`` (``--threads``; ``workers`` is a
    deprecated spelling, with a ``DeprecationWarning``), ``plots``, ``only_flagged``, ``images`` (fields of
    :class:`hpe_cli.pipelines.audit.AuditOptions`); ``consistency`` (True or a
    :class:`hpe_cli.pipelines.audit.consistency.Settings`, as ``--consistency``; report key ``consistency``) and
    ``suspects`` (path of the key list, as ``--suspects``).
    """

    opts = AuditOptions(report=report, output=output, overwrite=overwrite, rejects=rejects, strict=strict, **options)
    with ensure_transaction():
        return run_audit(input, None if system is None else get_system(system), opts)


def view_file(
    labels,
    output,
    other=None,
    *,
    images=None,
    system=None,
    other_system=None,
    keys=None,
    rejects=None,
    strict: bool = False,
    overwrite: bool = False,
    **options,
) -> dict:
    """``hpe view`` as a function: the same pipeline (:func:`hpe_cli.pipelines.view.run_view`).

    Writes a browsable offline page of every row of ``labels`` (and of ``other`` joined by ``keys`` beside it)
    into folder ``output``; open ``output/index.html``. Returns the counts (``rows``, ``shown``,
    ``whole_frame``, ``made``, ``reused``, ``images``, ``matched``, ``rejects``, ``system``). ``options``:
    the other :class:`~hpe_cli.pipelines.view.ViewOptions` fields (``radians``, ``use``, ``threads``,
    ``title``, ``frames``, ``also_in``: system names or ``.toml`` files whose angles the page can filter by).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import hpe_cli as hpe
    >>> aflw = pathlib.Path(hpe.__file__).parents[1] / "sample_data" / "aflw2000"  # 4 faces, .mat labels
    >>> with tempfile.TemporaryDirectory() as out:
    ...     s = hpe.view_file(aflw, pathlib.Path(out) / "page")
    >>> s["rows"], s["shown"], s["whole_frame"]  # .mat rows have no head box: shown whole
    (4, 4, 4)
    """

    settings = ViewOptions(
        images=images,
        system=None if system is None else get_system(system),
        other_system=None if other_system is None else get_system(other_system),
        keys=keys,
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        **options,
    )
    with ensure_transaction():
        return run_view(labels, output, other, settings)


def draw_file(
    input, output, *, images=None, system=None, rejects=None, strict: bool = False, overwrite: bool = False, **options
) -> dict:
    """``hpe draw`` as a function: the same pipeline (:func:`hpe_cli.pipelines.draw.run_draw`).

    Draws every row of the label table (or ``.mat`` folder) ``input`` on its image into folder ``output``
    (the per-row output of ``hpe evaluate -o``: ground truth and prediction on each face). Returns the counts
    (``faces``, ``images``, ``sheets``, ``rejects``, ``system``). ``options``: the other
    :class:`~hpe_cli.pipelines.draw.DrawOptions` fields (``style``, ``canvas``, ``radians``, ``use``,
    ``length``, ``thickness``, ``tdy_origin``, ``annotate``, ``grid``, ``grid_cols``, ``tile``, ``limit``,
    ``worst``, ``sort_by``, ``threads``).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import hpe_cli as hpe
    >>> aflw = pathlib.Path(hpe.__file__).parents[1] / "sample_data" / "aflw2000"  # 4 faces, .mat labels
    >>> with tempfile.TemporaryDirectory() as out:
    ...     s = hpe.draw_file(aflw, pathlib.Path(out) / "drawn", style="cube")
    >>> s["faces"], s["images"]
    (4, 4)
    """

    settings = DrawOptions(
        images=images,
        system=None if system is None else get_system(system),
        rejects=rejects,
        strict=strict,
        overwrite=overwrite,
        **options,
    )
    with ensure_transaction():
        return run_draw(input, output, settings)


def augment_file(input, output, op: str, angle=None, **settings) -> dict:
    """``hpe augment`` as a function: the same pipeline (:func:`hpe_cli.pipelines.augment.run_augment`).

    Parameters
    ----------
    input, output : str or path
        A label table (or a folder of ``.mat`` files); the ``.parquet`` or ``.csv`` to write.
    op : str
        ``hflip``, ``vflip``, ``hvflip``, ``rotate``, ``mirror``, ``crop`` or ``scale``.
    angle : float, optional
        Degrees counter-clockwise, for ``rotate`` and ``mirror``.
    **settings
        The other fields of :class:`hpe_cli.pipelines.augment.AugmentOptions` (``crop``, ``scale``,
        ``image_size``, ``system``, ``images_dir``, ``out_images``, ``rejects``, ``overwrite``...), checked once.

    Returns
    -------
    dict
        ``system``, ``rows``, ``written``, ``landmarks``, ``boxes``, ``images``, ``rejects`` (reason -> count).
    """

    opts = AugmentOptions(op=op, angle=angle, **settings)
    with ensure_transaction():
        return run_augment(input, output, opts)


def infer_system(data=None, *, code=None, output=None, **settings) -> dict:
    """``hpe infer`` as a function: the same pipeline (:func:`hpe_cli.pipelines.infer.run_infer`).

    Give ``data`` (a label table or ``.mat`` folder) or ``code`` (``FILE.py:FUNC`` or ``module:FUNC``, a decoder
    unless ``builder=True``). ``output``: write the matched system as TOML. ``settings``: the fields of
    :class:`hpe_cli.pipelines.infer.InferOptions` (``roles``, ``units``, ``angle_columns``, ``tol``, ``seed``,
    ``rejects``, ``overwrite``, ``threads``...), checked once.

    Returns
    -------
    dict
        The JSON report (``fit``, ``best``, ``system``...), as ``hpe infer --json`` writes it.

    Raises
    ------
    HpeError
        Nothing fits (with landmarks: no clear winner), as the command's exit status 1.
    """

    opts = InferOptions(**settings)
    with ensure_transaction():
        rep = run_infer(data, code, opts)
        report, _ = finish(rep, code or str(data), output=output, overwrite=opts.overwrite)
    return report


def write_labels(table, path, system=None, *, overwrite: bool = False):
    """Write a label table atomically (Parquet or CSV by extension), naming its system.

    Parameters
    ----------
    table : pandas.DataFrame, pyarrow.Table or dict of str to array_like
        One row per label (e.g. ``pitch, yaw, roll`` degrees, ``r00..r22``, ``bbox_*``, ``lm{i}_x/y``).
    path : str or path
        ``.parquet``/``.pq`` or ``.csv``. Parquet files get ``hpe:system`` and
        ``hpe:system_definition`` metadata, which :func:`read_labels` reads back.
    system : str, path or RotationSystem, optional
        The labels' system.
    overwrite : bool
        Replace an existing file (otherwise an ``HpeError``).

    Returns
    -------
    pathlib.Path
        The written file.

    Examples
    --------
    >>> import tempfile, os, hpe_cli as hpe
    >>> p = hpe.write_labels({"pitch": [0.5]}, os.path.join(tempfile.mkdtemp(), "x.csv"))
    >>> p.name, p.read_text().splitlines()[0]
    ('x.csv', '"pitch"')
    """

    if isinstance(table, dict):
        table = arrow_table(table)
    elif not isinstance(table, pa.Table):
        table = pa.Table.from_pandas(table, preserve_index=False)
    meta = None if system is None else system_metadata(get_system(system))
    return write_table(table, path, overwrite=overwrite, metadata=meta)


# --------------------------------------------------------------------------------------------- checks
def audit(values, system, storage: str | None = None, **options) -> dict:
    """Check head-pose labels row by row (the checks of ``hpe audit``).

    Parameters
    ----------
    values : array_like, shape (N, 3) or (N, 3, 3)
        ``(pitch, yaw, roll)`` degrees (NaN allowed), or stored matrices.
    system : str, path or RotationSystem
    storage : {"angles", "matrix"}, optional
        Default: ``matrix`` for 3-D input, else ``angles``.
    **options
        ``near_tol_deg`` (default 1), ``canonical_tol_deg`` (angles) or ``rotation_tol`` (matrices).

    Returns
    -------
    dict
        ``check -> bool array (N,)`` for ``gimbal_lock, near_gimbal, non_canonical,
        out_of_range, non_finite, not_rotation, duplicates`` and ``lock_distance`` (N,).

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> r = hpe.audit([[10, 20, 30], [-16.0909, -89.99858, -6.8545], [0, 120, 0], [0, 0, 0]], "300w_lp")
    >>> r["near_gimbal"].tolist(), r["non_canonical"].tolist()
    ([False, True, False, False], [False, False, True, False])
    """

    v = np.asarray(values, dtype=np.float64)
    if storage is None:
        storage = "matrix" if v.ndim == 3 else "angles"
    if storage == "angles":
        return audit_angles(v, system, **options)
    if storage == "matrix":
        return audit_matrices(v, system, **options)
    raise ValueError(f"expected storage 'angles' or 'matrix', got {storage!r}")


def evaluate(pred, gt, *, pred_system, gt_system, protocols=None, align: str = "none", columns=None) -> dict:
    """Evaluate predicted head poses against ground truth (the report of ``hpe evaluate``).

    Parameters
    ----------
    pred, gt : array_like, shape (N, 3) or (N, 3, 3)
        ``(pitch, yaw, roll)`` degrees or stored matrices of ``pred_system`` / ``gt_system``.
    pred_system, gt_system : str, path or RotationSystem
    protocols, align, columns
        See :func:`hpe_cli.metrics.evaluate.evaluate`.

    Returns
    -------
    dict
        The JSON report (MAE per angle, geodesic error, MAEV, ...).

    Raises
    ------
    NotImplementedError
        When this installation has no ``hpe_cli.metrics.evaluate``.

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> pred, gt = [[0.0, 12.0, 1.0], [5.0, -30.0, 0.0]], [[0.0, 10.0, 0.0], [4.0, -33.0, 2.0]]
    >>> report = hpe.evaluate(pred, gt, pred_system="300w_lp", gt_system="300w_lp")
    >>> report["n"]["pairs"], round(report["metrics"]["mae_wrapped"]["yaw"], 6)
    (2, 2.5)
    """

    if importlib.util.find_spec("hpe_cli.metrics.evaluate") is None:
        raise NotImplementedError(
            "hpe.evaluate needs hpe_cli.metrics.evaluate, which this installation does not have; upgrade hpe-cli"
        )

    return _evaluate(
        pred, gt, pred_system=pred_system, gt_system=gt_system, protocols=protocols, align=align, columns=columns
    )


def relabel_panoptic(seq_dirs, output, **options):
    """``hpe relabel-panoptic`` as a function: the same pipeline
    (:func:`hpe_cli.pipelines.relabel.run_relabel_panoptic`).

    Parameters
    ----------
    seq_dirs : path or list of paths
        CMU Panoptic sequences (``calibration_<seq>.json`` with ``hdFace3d/`` or ``hdFace3d.tar``), or folders
        of sequences.
    output : str or path
        A ``.parquet``/``.csv`` table, or with ``fmt="coco"`` a ``.json``, with ``fmt="whenet"`` a ``.txt``.
    **options
        The fields of :class:`hpe_cli.pipelines.relabel.RelabelPanopticOptions` (the command's options:
        ``system``, ``fmt``, ``cameras``, ``every``, ``frames``, ``max_rmse`` (cm), ``workers``, ``rejects``...).

    Returns
    -------
    PanopticRun
        ``stats`` (``labelled``, ``views``, ``view_reasons``, ...), ``per_sequence`` and ``summary()``, the
        command's summary lines.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import hpe_cli as hpe
    >>> seq = pathlib.Path(hpe.__file__).parents[1] / "sample_data" / "panoptic_160906_pizza1"
    >>> with tempfile.TemporaryDirectory() as out:
    ...     run = hpe.relabel_panoptic(seq, pathlib.Path(out) / "labels.parquet", landmarks=False,
    ...                                rejects=pathlib.Path(out) / "rejects.parquet")
    >>> run.stats.labelled, run.stats.views  # labels + rejects = every view
    (606, 713)
    """

    seq_dirs = [seq_dirs] if isinstance(seq_dirs, str) or hasattr(seq_dirs, "__fspath__") else list(seq_dirs)
    opts = RelabelPanopticOptions(**options)
    with ensure_transaction():
        return run_relabel_panoptic(seq_dirs, output, opts)


def relabel_agora(dataframes, output, **options):
    """``hpe relabel-agora`` as a function: the same pipeline (:func:`hpe_cli.pipelines.relabel.run_relabel_agora`).

    ``dataframes`` are AGORA ground-truth dataframes (``*_withjv.pkl`` or the same as Parquet), a path or a
    list; ``options`` are the fields of :class:`hpe_cli.pipelines.relabel.RelabelAgoraOptions` (``system``,
    ``fmt``, ``image_size``, ``max_rmse`` (m), ``max_occlusion``, ``rejects``, ``threads``...). Returns the counts
    (``people``, ``labelled``, ``reasons``; ``summary(...)``).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import hpe_cli as hpe
    >>> pkl = pathlib.Path(hpe.__file__).parents[1] / "tests" / "data" / "agora" / "validation_0_withjv.pkl"
    >>> with tempfile.TemporaryDirectory() as out:
    ...     s = hpe.relabel_agora(pkl, pathlib.Path(out) / "agora.parquet", rejects=pathlib.Path(out) / "r.csv")
    >>> s.labelled + sum(s.reasons.values()) == s.people  # every person labelled or a reject
    True
    """

    dataframes = [dataframes] if isinstance(dataframes, str) or hasattr(dataframes, "__fspath__") else list(dataframes)
    opts = RelabelAgoraOptions(**options)
    with ensure_transaction():
        return run_relabel_agora(dataframes, output, opts)


def biwi_file(input, output, **options) -> dict:
    """``hpe biwi`` as a function: the same pipeline (:func:`hpe_cli.pipelines.biwi.run_biwi`).

    ``input`` is BIWI's ``hpdb/``, ``db_annotations/`` or ``db_annotations.tgz``; ``output`` the label table;
    ``options`` the fields of :class:`hpe_cli.pipelines.biwi.BiwiOptions` (``camera``, ``calibration``,
    ``head_size`` (mm), ``system``, ``protocol``, ``split``, ``seed``, ``split_lists``, ``rejects``, ``threads``...),
    checked before anything is read. Returns the summary dict (``rows``, ``sequences``, ``splits``,
    ``rejected``...).

    Examples
    --------
    >>> import hpe_cli as hpe
    >>> hpe.biwi_file("hpdb", "biwi.parquet", split=(0.7, 0.4))
    Traceback (most recent call last):
    ...
    ValueError: expected two or three fractions >= 0 summing to 1, got (0.7, 0.4)
    """

    opts = BiwiOptions(**options)
    with ensure_transaction():
        return run_biwi(input, output, opts)


def evaluate_files(pred, gt, options=None, **settings) -> dict:
    """``hpe evaluate`` as a function: the same pipeline (:func:`hpe_cli.pipelines.evaluate.run_evaluate`).

    Parameters
    ----------
    pred, gt : str or path
        Any tables ``hpe`` reads (Parquet, CSV, JSON, a ``.mat`` folder, BIWI files...).
    options : EvaluateOptions, optional
        The run's settings (:class:`hpe_cli.pipelines.evaluate.EvaluateOptions`, as the command's options).
    **settings
        Fields of :class:`~hpe_cli.pipelines.evaluate.EvaluateOptions` (``pred_system``, ``gt_system``,
        ``keys``, ``protocols``, ``output``, ``report``, ``rejects``, ``threads``...) when ``options`` is not
        given.

    Returns
    -------
    dict
        The JSON report of ``hpe evaluate``.
    """

    if options is not None and settings:
        raise TypeError(f"expected options or settings, got both (settings: {', '.join(sorted(settings))})")
    with ensure_transaction():
        return run_evaluate(pred, gt, options if options is not None else EvaluateOptions(**settings))
