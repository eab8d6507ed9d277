"""CMU Panoptic relabelling as a streaming job (SPEC §6).

:func:`plan` picks the calibration, the cameras and the frames;
:func:`process_chunk` turns a chunk of frames into a table of labelled views
and a table of rejected ones (pure: no output, no printing); :func:`run`
streams chunks through :func:`process_chunk`, optionally in worker
processes, in frame order. Memory stays bounded by a few chunks whatever the
sequence length.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..datasets import panoptic as pan
from ..errors import HpeError
from ..geometry.reference import panoptic_pairs
from .relabel import DEFAULT_MAX_RMSE, LEGACY_COLS, REASONS, fit_faces, relabel_views, summary_tail, view_label_columns

CHUNK_FRAMES = 64
REJECT_COLS = ["sequence", "frame", "person_id", "camera", "reason", "detail", "fit_rmse", "n_pairs", "scale"]


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


@dataclass
class Plan:
    """The inputs of one run."""

    seq_dir: Path
    sequence: str
    calibration: Path
    cameras: pan.Cameras
    frames: dict  # frame -> Path, selected and sorted
    available: int  # face files in the folder
    missing: int  # frame numbers on the --every grid inside the range with no file
    chunks: list = field(default_factory=list)


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


def plan(seq_dir, calibration=None, cameras="hd", every: int = 1, frames=(None, None),
         chunk_frames: int = CHUNK_FRAMES) -> Plan:
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
    cams = pan.read_calibration(calib, cameras)
    wrong = [f"{n} ({t})" for n, t in zip(cams.names, cams.types) if t != "hd"]
    if wrong:
        raise HpeError(f"{calib}: hdFace3d frames are HD frames; expected hd cameras, got "
                       f"{', '.join(wrong[:3])}{' ...' if len(wrong) > 3 else ''} (other types run on another clock)")
    m = calib.name
    sequence = m[len("calibration_"):-len(".json")] if m.startswith("calibration_") and m.endswith(".json") \
        else seq_dir.resolve().name
    available = pan.face_frames(seq_dir)
    if not available:
        raise HpeError(f"{seq_dir}: no {pan.FACE_DIR}/faceRecon3D_hd*.json files")
    a, b = frames
    keys = np.fromiter(available.keys(), dtype=np.int64, count=len(available))
    start = a if a is not None else int(keys[0])
    sel = keys >= start
    if b is not None:
        sel &= keys < b
    sel &= (keys - start) % every == 0
    chosen = keys[sel]
    stop = (b - 1) if b is not None else int(keys[-1])
    last = min(stop, int(keys[-1]))
    grid = max(0, (last - start) // every + 1) if last >= start else 0
    selected = {int(f): available[int(f)] for f in chosen}
    if not selected:
        raise HpeError(f"{seq_dir}: no face frame matches --frames {a if a is not None else ''}:"
                       f"{b if b is not None else ''} --every {every} (frames {keys[0]}..{keys[-1]} exist)")
    items = list(selected.items())
    chunks = [dict(items[i:i + chunk_frames]) for i in range(0, len(items), chunk_frames)]
    return Plan(seq_dir, sequence, calib, cams, selected, len(available), grid - len(selected), chunks)


def process_chunk(paths: dict, cams: pan.Cameras, sequence: str, cfg: Config) -> dict:
    """Relabel one chunk of frames seen by all ``cams``.

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
    fit = fit_faces(data["landmarks"], data["score"], panoptic_pairs(), conf_min=cfg.conf_min,
                    min_pair_count=cfg.min_pairs, max_rmse=cfg.max_rmse)
    face = np.repeat(np.arange(n), C)
    ci = np.tile(np.arange(C), n)
    cam = {"K": cams.K[ci], "dist": cams.dist[ci], "R": cams.R[ci], "t": cams.t[ci],
           "width": cams.width[ci], "height": cams.height[ci]}
    v = relabel_views(fit, face, cam, cfg.system, preset=cfg.preset, legacy=cfg.legacy,
                      landmarks=data["landmarks"] if cfg.landmarks else None)
    ok = v["ok"]
    fo, co = face[ok], ci[ok]
    frames = data["frame"][fo]
    names = cams.names[co]
    table = {
        "sequence": np.full(len(fo), sequence, dtype=object),
        "frame": frames,
        "camera": names,
        "person_id": data["person_id"][fo],
        "image": _image_paths(cams, co, frames),
    }
    table.update(view_label_columns(v, fit, fo, cfg.legacy))
    table["image_width"] = cams.width[co]
    table["image_height"] = cams.height[co]
    bad = ~ok
    fb = face[bad]
    rejects = {
        "sequence": np.full(len(fb), sequence, dtype=object),
        "frame": data["frame"][fb], "person_id": data["person_id"][fb], "camera": cams.names[ci[bad]],
        "reason": v["reason"][bad], "detail": v["detail"][bad],
        "fit_rmse": fit["rmse"][fb], "n_pairs": fit["n_pairs"][fb], "scale": fit["scale"][fb],
    }
    fitted = np.isfinite(fit["rmse"])
    legacy_considered = int(np.isin(v["reason"], ("", "dropped by legacy rule")).sum()) if cfg.legacy else 0
    return {"table": table, "rejects": rejects, "faces": n, "fit_rmse": fit["rmse"][fitted],
            "face_reasons": fit["reason"], "views": n * C, "legacy_considered": legacy_considered,
            "frames": len(paths)}


def _image_paths(cams: pan.Cameras, ci, frames):
    """``hdImgs/<cam>/<cam>_<frame>.jpg`` per row, joined in Arrow (no Python loop per row)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    prefix = pa.array([pan.image_path(c, 0, t)[:-len("00000000.jpg")] for c, t in zip(cams.names, cams.types)],
                      type=pa.string())
    uniq, inv = np.unique(frames, return_inverse=True)
    names = pa.array([f"{int(f):08d}.jpg" for f in uniq], type=pa.string())
    return pc.binary_join_element_wise(prefix.take(pa.array(ci)), names.take(pa.array(inv.reshape(-1))), "")


# -------------------------------------------------------------- streaming
_WORKER: dict = {}


def _init_worker(cams, sequence, cfg):
    _WORKER.update(cams=cams, sequence=sequence, cfg=cfg)


def _work(paths):
    return process_chunk(paths, _WORKER["cams"], _WORKER["sequence"], _WORKER["cfg"])


def run(p: Plan, cfg: Config, workers: int = 1):
    """Yield :func:`process_chunk` results for every chunk of ``p``, in order.

    With ``workers > 1`` chunks are computed in worker processes, at most
    ``2 * workers`` at a time, so memory stays bounded.
    """
    if workers <= 1 or len(p.chunks) <= 1:
        for chunk in p.chunks:
            yield process_chunk(chunk, p.cameras, p.sequence, cfg)
        return
    import multiprocessing as mp
    from collections import deque
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("spawn" if mp.get_start_method(allow_none=True) == "spawn" else "fork")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                             initargs=(p.cameras, p.sequence, cfg)) as ex:
        pending: deque = deque()
        it = iter(p.chunks)
        for chunk in it:
            pending.append(ex.submit(_work, chunk))
            if len(pending) >= 2 * workers:
                break
        while pending:
            res = pending.popleft().result()
            nxt = next(it, None)
            if nxt is not None:
                pending.append(ex.submit(_work, nxt))
            yield res


class RmseStats:
    """Fixed-size histogram of fit RMSE values (flat memory) for the summary."""

    EDGES = np.concatenate([np.arange(0.0, 20.0, 0.01), [np.inf]])

    def __init__(self):
        self.counts = np.zeros(len(self.EDGES) - 1, dtype=np.int64)
        self.n = 0
        self.max = -np.inf

    def add(self, values) -> None:
        values = np.asarray(values, dtype=np.float64)
        if values.size:
            self.counts += np.histogram(values, self.EDGES)[0]
            self.n += values.size
            self.max = max(self.max, float(values.max()))

    def quantile(self, q: float) -> float:
        """Upper edge of the 0.01-wide bin holding quantile ``q`` (capped at the max)."""
        if not self.n:
            return float("nan")
        k = int(np.searchsorted(np.cumsum(self.counts), q * self.n, side="left"))
        return float(min(self.EDGES[min(k + 1, len(self.EDGES) - 2)], self.max))


class Stats:
    """Counts for the end-of-run summary; every face and view is accounted for."""

    def __init__(self):
        from collections import Counter

        self.frames = self.faces = self.views = self.labelled = 0
        self.legacy_considered = self.out_of_range = self.gimbal = 0
        self.view_reasons: Counter = Counter()
        self.face_reasons: Counter = Counter()
        self.rmse = RmseStats()

    def add(self, res: dict, cfg: Config) -> None:
        from ..rotation import get_system

        self.frames += res["frames"]
        self.faces += res["faces"]
        self.views += res["views"]
        t = res["table"]
        self.labelled += len(t["frame"])
        self.view_reasons.update(res["rejects"]["reason"].tolist())
        self.face_reasons.update(r for r in res["face_reasons"].tolist() if r)
        self.rmse.add(res["fit_rmse"])
        self.legacy_considered += res["legacy_considered"]
        if len(t["frame"]):
            pyr = np.stack([t["pitch"], t["yaw"], t["roll"]], axis=1)
            self.out_of_range += int((~get_system(cfg.system).in_range(pyr)).sum())
            self.gimbal += int(np.sum(t["gimbal_lock"]))

    def summary(self, p: Plan, cfg: Config, output, rejects_path) -> list:
        sysname = getattr(cfg.system, "name", cfg.system)
        nums = list(p.frames)
        span = f"{nums[0]}..{nums[-1]}" if nums else "none"
        gaps = f"; {p.missing} frame numbers on that grid have no face file" if p.missing else ""
        lines = [f"{p.sequence}: {self.frames} frames ({span}{gaps}), "
                 f"{self.faces} faces x {len(p.cameras)} cameras = {self.views} views"]
        fitted = self.faces - self.face_reasons["too few confident points"]
        gate = "off" if cfg.max_rmse is None or not np.isfinite(cfg.max_rmse) else f"{cfg.max_rmse:g}"
        lines.append(f"faces: {fitted} fitted; {self.face_reasons['too few confident points']} with too few "
                     f"confident points; {self.face_reasons['bad fit']} bad fits (--max-rmse {gate})")
        if self.rmse.n:
            lines.append(f"fit RMSE (cm) of fitted faces: median {self.rmse.quantile(0.5):.2f}, "
                         f"p95 {self.rmse.quantile(0.95):.2f}, p99 {self.rmse.quantile(0.99):.2f}, "
                         f"max {self.rmse.max:.2f}")
        pct = 100.0 * self.labelled / self.views if self.views else 0.0
        lines.append(f"labelled {self.labelled} of {self.views} views ({pct:.1f}%) in {sysname} -> {output}")
        rej = sum(self.view_reasons.values())
        if rej:
            parts = "; ".join(f"{n} {r}" for r, n in sorted(self.view_reasons.items(), key=lambda x: -x[1]))
            lines.append(f"rejected {rej} views: {parts}" + (f" -> {rejects_path}" if rejects_path else ""))
        lines += summary_tail(cfg.legacy, self.view_reasons["dropped by legacy rule"], self.legacy_considered,
                              self.out_of_range, self.gimbal, sysname, "views", "WHENet")
        return lines






def _reject_schema():
    import pyarrow as pa

    return pa.schema([("sequence", pa.string()), ("frame", pa.int64()), ("person_id", pa.int64()),
                      ("camera", pa.string()), ("reason", pa.string()), ("detail", pa.string()),
                      ("fit_rmse", pa.float64()), ("n_pairs", pa.int64()), ("scale", pa.float64())])


def write_outputs(p: Plan, cfg: Config, output, fmt: str = "table", rejects_path=None, overwrite: bool = False,
                  workers: int = 1, bar=None) -> Stats:
    """Run the job and write its outputs atomically; return the :class:`Stats`.

    ``fmt`` is ``table`` (streamed to Parquet/CSV), ``coco`` or ``whenet``
    (collected, then written by :mod:`hpe_cli.io.coco` /
    :mod:`hpe_cli.io.whenet_txt`). The rejects table is streamed too.
    """
    import json
    from contextlib import ExitStack

    from ..io import TableWriter, arrow_table, check_output, system_metadata
    from ..rotation import get_system

    system = get_system(cfg.system)
    stats = Stats()
    meta = {**system_metadata(system), "hpe:relabel": json.dumps({
        "source": "cmu_panoptic", "sequence": p.sequence, "calibration": str(p.calibration),
        "cameras": list(map(str, p.cameras.names)), "preset": cfg.preset,
        "max_rmse": cfg.max_rmse if cfg.max_rmse is not None and np.isfinite(cfg.max_rmse) else None,
        "legacy_whenet": cfg.legacy, "label": "A = E @ R_cam @ R_head, E = diag(1, -1, -1)"})}
    collected = []
    rschema = _reject_schema()
    with ExitStack() as stack:
        if fmt == "table":
            out = stack.enter_context(TableWriter(output, overwrite, meta))
        else:
            check_output(output, overwrite)
            out = None
        rej = stack.enter_context(TableWriter(rejects_path, overwrite)) if rejects_path else None
        for res in run(p, cfg, workers):
            stats.add(res, cfg)
            t = arrow_table(res["table"])
            if out is not None:
                out.write(t)
            else:
                collected.append(t)
            if rej is not None:
                rej.write(arrow_table(res["rejects"], rschema))
            if bar is not None:
                bar.update(res["frames"])
        if fmt != "table":
            import pyarrow as pa

            frame = pa.concat_tables(collected).to_pandas()
            _write_other(fmt, frame, output, overwrite)
    return stats


def _write_other(fmt: str, frame, output, overwrite: bool) -> None:
    try:
        if fmt == "coco":
            from ..io.coco import write_coco as writer
        else:
            from ..io.whenet_txt import write_whenet as writer
    except ImportError:
        raise HpeError(f"--format {fmt}: its writer (hpe_cli.io.{'coco' if fmt == 'coco' else 'whenet_txt'}) "
                       "is not available in this build") from None
    if fmt == "coco":
        writer(frame, output, overwrite=overwrite, image_size_cols=("image_width", "image_height"))
    else:
        writer(frame, output, overwrite=overwrite)


__all__ = ["Config", "Plan", "plan", "process_chunk", "run", "write_outputs", "parse_frames", "Stats",
           "RmseStats", "REASONS", "CHUNK_FRAMES", "LEGACY_COLS", "REJECT_COLS"]
