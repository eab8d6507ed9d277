"""CMU Panoptic relabelling, planning and the pure unit computation (SPEC §6).

:func:`plan` picks the calibration, the cameras and the frames of one
sequence (and the frames ``--every`` skips, which are read only to list their
views in the rejects); :func:`process_chunk` turns a chunk of frames into a
table of labelled views and a table of rejected ones (pure: no output, no
printing).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ...datasets import panoptic as pan
from ...errors import HpeError
from ...geometry.reference import panoptic_pairs
from ...io.layout import numpy_to_arrow, string_array
from ...rotation.systems import get_system
from .core import DEFAULT_MAX_RMSE, fit_faces, relabel_views, view_label_columns

CHUNK_FRAMES = 64
REJECT_COLS = ["sequence", "frame", "person_id", "camera", "reason", "detail", "fit_rmse", "n_pairs", "scale"]

#: WHENet's 20 HD cameras for the haggling sequences: ``without_top`` in
#: Ascend-Research/HeadPoseEstimation-WHENet ``prepare_images.py`` (nodes of panel 0;
#: the cameras it skips look down from the top of the dome)
WHENET_HAGGLING = tuple(
    f"00_{i:02d}" for i in (0, 3, 5, 8, 9, 11, 12, 14, 15, 16, 18, 20, 21, 22, 23, 24, 25, 26, 27, 29)
)
CAMERA_PRESETS = {"whenet-haggling": ",".join(WHENET_HAGGLING)}


@dataclass
class Config:
    """What to compute for each view (everything but I/O)."""

    system: object = "300w_lp"
    preset: str = "whenet"
    max_rmse: float | None = DEFAULT_MAX_RMSE
    legacy: bool = False
    landmarks: bool = True
    conf_min: float | None = None
    min_pairs: int | None = None
    frame: str = "camera"  # "camera" or "crop" (line of sight, SPEC §10)
    all_views: bool = False  # keep a face only if every selected camera labels it
    min_change: float | None = None  # degrees, per (sequence, person, camera); applied in order by the writer

    def __post_init__(self):
        # resolved once here, before the config travels to worker processes (library callers pass a name)
        self.system = get_system(self.system)


@dataclass
class Plan:
    """The inputs of one sequence."""

    seq_dir: Path
    sequence: str
    calibration: Path
    cameras: pan.Cameras
    frames: dict  # frame -> FaceRef, selected and sorted
    available: int  # face files in the folder or tar
    missing: int  # frame numbers on the --every grid inside the range with no file
    chunks: list = field(default_factory=list)
    every: int = 1
    #: per chunk, the face files inside the range that ``--every`` skips (frame -> FaceRef), read only to list
    #: their views in the rejects ("skipped by --every"), so labels + rejects = every view of the range
    skipped: list = field(default_factory=list)


def parse_frames(spec: str | None) -> tuple:
    """``"A:B"`` -> (A, B) meaning ``A <= frame < B``; either side may be empty."""
    if spec is None or spec == "":
        return (None, None)
    parts = spec.split(":")
    if len(parts) != 2:
        raise ValueError(f"expected A:B (frame numbers, A included, B excluded), got {spec!r}")
    try:
        a = int(parts[0]) if parts[0].strip() else None
        b = int(parts[1]) if parts[1].strip() else None
    except ValueError:
        raise ValueError(f"expected integer frame numbers in A:B, got {spec!r}") from None
    if a is not None and b is not None and b <= a:
        raise ValueError(f"expected A < B in --frames A:B, got {spec!r}")
    return (a, b)


def plan(
    seq_dir, calibration=None, cameras="hd", every: int = 1, frames=(None, None), chunk_frames: int = CHUNK_FRAMES
) -> Plan:
    """Resolve the calibration, cameras and frames of a sequence folder.

    Frames are looked up by number: with ``every = N`` the frames kept are
    ``start, start + N, ...`` where ``start`` is ``A`` of ``frames`` or the
    first face file; numbers on that grid with no file are counted as
    ``missing`` (gaps are normal in Panoptic).
    """
    seq_dir = Path(seq_dir)
    if not seq_dir.is_dir():
        raise HpeError(f"{seq_dir}: not a folder")
    calib = Path(calibration) if calibration else pan.find_calibration(seq_dir)
    if isinstance(cameras, str):
        cameras = CAMERA_PRESETS.get(cameras, cameras)
    cams = pan.read_calibration(calib, cameras)
    wrong = [f"{n} ({t})" for n, t in zip(cams.names, cams.types) if t != "hd"]
    if wrong:
        raise HpeError(
            f"{calib}: hdFace3d frames are HD frames; expected hd cameras, got "
            f"{', '.join(wrong[:3])}{' ...' if len(wrong) > 3 else ''} (other types run on another clock)"
        )
    m = calib.name
    sequence = (
        m[len("calibration_") : -len(".json")]
        if m.startswith("calibration_") and m.endswith(".json")
        else seq_dir.resolve().name
    )
    available = pan.face_sources(seq_dir)
    if not available:
        raise HpeError(f"{seq_dir}: no {pan.FACE_DIR}/faceRecon3D_hd*.json files")
    a, b = frames
    keys = np.fromiter(available.keys(), dtype=np.int64, count=len(available))
    start = a if a is not None else int(keys[0])
    sel = keys >= start
    if b is not None:
        sel &= keys < b
    on_grid = (keys - start) % every == 0
    off_grid = keys[sel & ~on_grid]
    sel &= on_grid
    chosen = keys[sel]
    stop = (b - 1) if b is not None else int(keys[-1])
    last = min(stop, int(keys[-1]))
    grid = max(0, (last - start) // every + 1) if last >= start else 0
    selected = {int(f): available[int(f)] for f in chosen}
    if not selected:
        raise HpeError(
            f"{seq_dir}: no face frame matches --frames {a if a is not None else ''}:"
            f"{b if b is not None else ''} --every {every} (frames {keys[0]}..{keys[-1]} exist)"
        )
    items = list(selected.items())
    chunks = [dict(items[i : i + chunk_frames]) for i in range(0, len(items), chunk_frames)]
    # each skipped frame goes with the chunk whose frames surround it (the first chunk for those before it)
    starts = np.asarray([next(iter(c)) for c in chunks], dtype=np.int64)
    owner = np.maximum(np.searchsorted(starts, off_grid, side="right") - 1, 0)
    skipped: list = [{} for _ in chunks]
    for f, k in zip(off_grid.tolist(), owner.tolist()):
        skipped[k][int(f)] = available[int(f)]
    return Plan(seq_dir, sequence, calib, cams, selected, len(available), grid - len(selected), chunks, every, skipped)


def find_sequences(paths) -> list:
    """Sequence folders from the command line: each path is a sequence, or a
    root whose sub-folders (sorted by name) are sequences."""
    out = []
    for p in map(Path, paths):
        if not p.is_dir():
            raise HpeError(f"{p}: not a folder")
        if pan.is_sequence(p) or (p / pan.FACE_DIR).is_dir() or (p / pan.FACE_TAR).is_file() or p.name == pan.FACE_DIR:
            out.append(p)
            continue
        subs = sorted(q for q in p.iterdir() if q.is_dir() and pan.is_sequence(q))
        if not subs:
            raise HpeError(
                f"{p}: neither a sequence (calibration_<seq>.json with hdFace3d/ or hdFace3d.tar) "
                "nor a folder of sequences"
            )
        out += subs
    seen: dict = {}
    for p in out:
        key = p.resolve()
        if key in seen:
            raise HpeError(f"{seen[key]} and {p}: the same sequence is given twice")
        seen[key] = p
    return out


def plan_many(
    paths, calibration=None, cameras="hd", every: int = 1, frames=(None, None), chunk_frames: int = CHUNK_FRAMES
) -> list:
    """:func:`plan` for every sequence of :func:`find_sequences` (``--calibration`` only with one)."""
    seqs = find_sequences(paths)
    if calibration and len(seqs) > 1:
        raise HpeError(f"--calibration names one file but {len(seqs)} sequences are given")
    plans = [plan(s, calibration, cameras, every, frames, chunk_frames) for s in seqs]
    names: dict = {}
    for p in plans:
        if p.sequence in names:
            raise HpeError(f"{names[p.sequence]} and {p.seq_dir}: both are sequence {p.sequence!r}")
        names[p.sequence] = p.seq_dir
    return plans


def process_chunk(
    paths: dict, cams: pan.Cameras, sequence: str, cfg: Config, skipped: dict | None = None, every: int = 1
) -> dict:
    """Relabel one chunk of frames seen by all ``cams``; list the views of the ``skipped`` frames
    (frame -> face file, skipped by ``--every``) as rejects.

    Returns
    -------
    dict
        ``table``: dict of output columns (labelled views, frame-person-camera
        order); ``rejects``: dict of reject columns (:data:`REJECT_COLS`);
        ``faces`` (int), ``fit_rmse`` (faces,) of fitted faces, ``face_reasons``
        (list of face-level reasons), ``legacy_considered`` (int).
    """

    data = pan.read_face_frames(paths)
    n = len(data["frame"])
    C = len(cams)
    fit = fit_faces(
        data["landmarks"],
        data["score"],
        panoptic_pairs(),
        conf_min=cfg.conf_min,
        min_pair_count=cfg.min_pairs,
        max_rmse=cfg.max_rmse,
    )
    face = np.repeat(np.arange(n), C)
    ci = np.tile(np.arange(C), n)
    cam = {
        "K": cams.K[ci],
        "dist": cams.dist[ci],
        "R": cams.R[ci],
        "t": cams.t[ci],
        "width": cams.width[ci],
        "height": cams.height[ci],
    }
    v = relabel_views(
        fit,
        face,
        cam,
        cfg.system,
        preset=cfg.preset,
        legacy=cfg.legacy,
        landmarks=data["landmarks"] if cfg.landmarks else None,
        frame=cfg.frame,
    )
    if cfg.all_views and n:
        _every_camera_rule(v, n, C)
    ok = v["ok"]
    fo, co = face[ok], ci[ok]
    frames = data["frame"][fo]
    table = {  # strings taken in Arrow from the few distinct values (no Python object per row)
        "sequence": string_array([sequence]).take(numpy_to_arrow(np.zeros(len(fo), dtype=np.int64))),
        "frame": frames,
        "camera": string_array(cams.names).take(numpy_to_arrow(co)),
        "person_id": data["person_id"][fo],
        "image": image_paths(cams, co, frames),
    }
    table.update(view_label_columns(v, fit, fo, cfg.legacy))
    table["image_width"] = cams.width[co]
    table["image_height"] = cams.height[co]
    fitted = np.isfinite(fit["rmse"])
    legacy_considered = int(np.isin(v["reason"], ("", "dropped by legacy rule")).sum()) if cfg.legacy else 0
    res = {
        "table": table,
        "rejects": _view_rejects(data, v, fit, face[~ok], ci[~ok], cams, sequence),
        "faces": n,
        "fit_rmse": fit["rmse"][fitted],
        "face_reasons": fit["reason"],
        "views": n * C,
        "legacy_considered": legacy_considered,
        "frames": len(paths),
        "unreadable": len(data["unreadable"]),
    }
    if skipped:
        _add_skipped(res, skipped, cams, sequence, every)
    return res


def _every_camera_rule(v: dict, n: int, C: int) -> None:
    """``--all-views``: a face that some but not all of the ``C`` cameras label goes to the rejects in every
    view ("not seen by every camera"); ``v`` (:func:`~.core.relabel_views` of ``n`` faces) is updated."""
    ok = v["ok"]
    seen = ok.reshape(n, C).sum(1)
    drop = np.repeat((seen > 0) & (seen < C), C) & ok
    if not drop.any():
        return
    v["reason"][drop] = "not seen by every camera"
    v["detail"][drop] = np.repeat(np.asarray([f"{k} of {C} cameras label this face" for k in seen], dtype=object), C)[
        drop
    ]
    keep = ~drop[ok]
    conv = v["conversion"]
    v["conversion"] = type(conv)(
        *(
            getattr(conv, f)[keep]
            for f in ("primary", "secondary", "matrix", "gimbal_lock", "roundtrip_err", "canonical")
        )
    )
    v["ok"] = ok & ~drop


def _view_rejects(data: dict, v: dict, fit: dict, fb, cb, cams: pan.Cameras, sequence: str) -> dict:
    """The reject columns (:data:`REJECT_COLS`): the views not labelled (faces ``fb`` seen by cameras ``cb``),
    then the unreadable face files."""
    bad = ~v["ok"]
    unread = data["unreadable"]
    u = len(unread)
    return {
        "sequence": np.full(len(fb) + u, sequence, dtype=object),
        "frame": np.concatenate([data["frame"][fb], np.asarray([f for f, _, _ in unread], dtype=np.int64)]),
        "person_id": np.concatenate([data["person_id"][fb], np.full(u, -1, dtype=np.int64)]),
        "camera": np.concatenate([cams.names[cb], np.full(u, "", dtype=object)]),
        "reason": np.concatenate([v["reason"][bad], np.asarray([r for _, r, _ in unread], dtype=object)]),
        "detail": np.concatenate([v["detail"][bad], np.asarray([d for _, _, d in unread], dtype=object)]),
        "fit_rmse": np.concatenate([fit["rmse"][fb], np.full(u, np.nan)]),
        "n_pairs": np.concatenate([fit["n_pairs"][fb], np.full(u, 0, dtype=np.int64)]),
        "scale": np.concatenate([fit["scale"][fb], np.full(u, np.nan)]),
    }


SKIPPED = "skipped by --every"
#: reject reasons of the sampling rules a user asks for (not failures: ``--strict`` ignores them)
SAMPLING_REASONS = (SKIPPED, "below --min-change", "not seen by every camera")


def _add_skipped(res: dict, skipped: dict, cams: pan.Cameras, sequence: str, every: int) -> None:
    """Append one reject per view of the frames ``--every`` skipped (their faces are read, not fitted) and
    count them: frames, faces (face reason :data:`SKIPPED`) and views."""
    data = pan.read_face_frames(skipped)
    n, C = len(data["frame"]), len(cams)
    face = np.repeat(np.arange(n), C)
    ci = np.tile(np.arange(C), n)
    unread = data["unreadable"]
    u = len(unread)
    frames = np.concatenate([data["frame"][face], np.asarray([f for f, _, _ in unread], dtype=np.int64)])
    detail = np.asarray(
        [f"--every {every}: frame {f} is not on the grid of frames kept" for f in frames.tolist()], dtype=object
    )
    detail[n * C :] = [d for _, _, d in unread]
    add = {
        "sequence": np.full(n * C + u, sequence, dtype=object),
        "frame": frames,
        "person_id": np.concatenate([data["person_id"][face], np.full(u, -1, dtype=np.int64)]),
        "camera": np.concatenate([np.asarray(cams.names, dtype=object)[ci], np.full(u, "", dtype=object)]),
        "reason": np.asarray([SKIPPED] * (n * C) + [r for _, r, _ in unread], dtype=object),
        "detail": detail,
        "fit_rmse": np.full(n * C + u, np.nan),
        "n_pairs": np.zeros(n * C + u, dtype=np.int64),
        "scale": np.full(n * C + u, np.nan),
    }
    rej = res["rejects"]
    for k in rej:
        rej[k] = np.concatenate([np.asarray(rej[k], dtype=add[k].dtype), add[k]])
    res["face_reasons"] = np.concatenate(
        [np.asarray(res["face_reasons"], dtype=object), np.full(n, SKIPPED, dtype=object)]
    )
    res["faces"] += n
    res["views"] += n * C
    res["frames"] += len(skipped)
    res["unreadable"] += u
    res["skipped_frames"] = len(skipped)
    res["every"] = int(every)


def image_paths(cams: pan.Cameras, ci, frames):
    """``hdImgs/<cam>/<cam>_<frame>.jpg`` per row (:func:`hpe_cli.datasets.panoptic.image_path`), joined in
    Arrow from the cameras' prefixes and the distinct frames' names (no Python step per row, and no
    ``pa.array``, which imports pandas: 0.3 s in every worker)."""
    ci = np.asarray(ci, dtype=np.int64).reshape(-1)
    tail = len("00000000.jpg")
    prefix = string_array([pan.image_path(c, 0, t)[:-tail] for c, t in zip(cams.names, cams.types)])
    uniq, inv = np.unique(np.asarray(frames, dtype=np.int64).reshape(-1), return_inverse=True)
    names = string_array([f"{f:08d}.jpg" for f in uniq.tolist()])
    n = len(ci)
    empty = pa.StringArray.from_buffers(n, pa.py_buffer(np.zeros(n + 1, dtype=np.int32)), pa.py_buffer(b""))
    return pc.binary_join_element_wise(
        prefix.take(numpy_to_arrow(ci)), names.take(numpy_to_arrow(inv.reshape(-1))), empty
    )
