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

#: WHENet's 20 HD cameras for the haggling sequences: ``without_top`` in
#: Ascend-Research/HeadPoseEstimation-WHENet ``prepare_images.py`` (nodes of panel 0;
#: the cameras it skips look down from the top of the dome)
WHENET_HAGGLING = tuple(f"00_{i:02d}" for i in (0, 3, 5, 8, 9, 11, 12, 14, 15, 16, 18, 20, 21, 22, 23, 24, 25,
                                                 26, 27, 29))
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
    if isinstance(cameras, str):
        cameras = CAMERA_PRESETS.get(cameras, cameras)
    cams = pan.read_calibration(calib, cameras)
    wrong = [f"{n} ({t})" for n, t in zip(cams.names, cams.types) if t != "hd"]
    if wrong:
        raise HpeError(f"{calib}: hdFace3d frames are HD frames; expected hd cameras, got "
                       f"{', '.join(wrong[:3])}{' ...' if len(wrong) > 3 else ''} (other types run on another clock)")
    m = calib.name
    sequence = m[len("calibration_"):-len(".json")] if m.startswith("calibration_") and m.endswith(".json") \
        else seq_dir.resolve().name
    available = pan.face_sources(seq_dir)
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


def find_sequences(paths) -> list:
    """Sequence folders from the command line: each path is a sequence, or a
    root whose sub-folders (sorted by name) are sequences."""
    out = []
    for p in map(Path, paths):
        if not p.is_dir():
            raise HpeError(f"{p}: not a folder")
        if pan.is_sequence(p) or (p / pan.FACE_DIR).is_dir() or (p / pan.FACE_TAR).is_file() \
                or p.name == pan.FACE_DIR:
            out.append(p)
            continue
        subs = sorted(q for q in p.iterdir() if q.is_dir() and pan.is_sequence(q))
        if not subs:
            raise HpeError(f"{p}: neither a sequence (calibration_<seq>.json with hdFace3d/ or hdFace3d.tar) "
                           "nor a folder of sequences")
        out += subs
    seen: dict = {}
    for p in out:
        key = p.resolve()
        if key in seen:
            raise HpeError(f"{seen[key]} and {p}: the same sequence is given twice")
        seen[key] = p
    return out


def plan_many(paths, calibration=None, cameras="hd", every: int = 1, frames=(None, None),
              chunk_frames: int = CHUNK_FRAMES) -> list:
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

    from ..io.layout import numpy_to_arrow, string_array

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
                      landmarks=data["landmarks"] if cfg.landmarks else None, frame=cfg.frame)
    ok = v["ok"]
    if cfg.all_views and n:
        seen = ok.reshape(n, C).sum(1)
        drop = np.repeat((seen > 0) & (seen < C), C) & ok
        if drop.any():
            v["reason"][drop] = "not seen by every camera"
            v["detail"][drop] = np.repeat(np.asarray([f"{k} of {C} cameras label this face" for k in seen],
                                                     dtype=object), C)[drop]
            keep = ~drop[ok]
            conv = v["conversion"]
            v["conversion"] = type(conv)(*(getattr(conv, f)[keep] for f in
                                           ("primary", "secondary", "matrix", "gimbal_lock", "roundtrip_err",
                                            "canonical")))
            ok = ok & ~drop
            v["ok"] = ok
    fo, co = face[ok], ci[ok]
    frames = data["frame"][fo]
    table = {  # strings taken in Arrow from the few distinct values (no Python object per row)
        "sequence": string_array([sequence]).take(numpy_to_arrow(np.zeros(len(fo), dtype=np.int64))),
        "frame": frames,
        "camera": string_array(cams.names).take(numpy_to_arrow(co)),
        "person_id": data["person_id"][fo],
        "image": _image_paths(cams, co, frames),
    }
    table.update(view_label_columns(v, fit, fo, cfg.legacy))
    table["image_width"] = cams.width[co]
    table["image_height"] = cams.height[co]
    bad = ~ok
    fb = face[bad]
    unread = data["unreadable"]
    u = len(unread)
    rejects = {
        "sequence": np.full(len(fb) + u, sequence, dtype=object),
        "frame": np.concatenate([data["frame"][fb], np.asarray([f for f, _, _ in unread], dtype=np.int64)]),
        "person_id": np.concatenate([data["person_id"][fb], np.full(u, -1, dtype=np.int64)]),
        "camera": np.concatenate([cams.names[ci[bad]], np.full(u, "", dtype=object)]),
        "reason": np.concatenate([v["reason"][bad], np.asarray([r for _, r, _ in unread], dtype=object)]),
        "detail": np.concatenate([v["detail"][bad], np.asarray([d for _, _, d in unread], dtype=object)]),
        "fit_rmse": np.concatenate([fit["rmse"][fb], np.full(u, np.nan)]),
        "n_pairs": np.concatenate([fit["n_pairs"][fb], np.full(u, 0, dtype=np.int64)]),
        "scale": np.concatenate([fit["scale"][fb], np.full(u, np.nan)]),
    }
    fitted = np.isfinite(fit["rmse"])
    legacy_considered = int(np.isin(v["reason"], ("", "dropped by legacy rule")).sum()) if cfg.legacy else 0
    return {"table": table, "rejects": rejects, "faces": n, "fit_rmse": fit["rmse"][fitted],
            "face_reasons": fit["reason"], "views": n * C, "legacy_considered": legacy_considered,
            "frames": len(paths), "unreadable": u}


def _image_paths(cams: pan.Cameras, ci, frames):
    """``hdImgs/<cam>/<cam>_<frame>.jpg`` per row (:func:`hpe_cli.datasets.panoptic.image_path`), joined in
    Arrow from the cameras' prefixes and the distinct frames' names (no Python step per row, and no
    ``pa.array``, which imports pandas: 0.3 s in every worker)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from ..io.layout import numpy_to_arrow, string_array

    ci = np.asarray(ci, dtype=np.int64).reshape(-1)
    tail = len("00000000.jpg")
    prefix = string_array([pan.image_path(c, 0, t)[:-tail] for c, t in zip(cams.names, cams.types)])
    uniq, inv = np.unique(np.asarray(frames, dtype=np.int64).reshape(-1), return_inverse=True)
    names = string_array([f"{f:08d}.jpg" for f in uniq.tolist()])
    n = len(ci)
    empty = pa.StringArray.from_buffers(n, pa.py_buffer(np.zeros(n + 1, dtype=np.int32)), pa.py_buffer(b""))
    return pc.binary_join_element_wise(prefix.take(numpy_to_arrow(ci)), names.take(numpy_to_arrow(inv.reshape(-1))),
                                       empty)


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

    def merge(self, other: "RmseStats") -> None:
        self.counts += other.counts
        self.n += other.n
        self.max = max(self.max, other.max)

    def to_dict(self) -> dict:
        nz = np.flatnonzero(self.counts)
        return {"bins": nz.tolist(), "counts": self.counts[nz].tolist(), "n": self.n,
                "max": self.max if np.isfinite(self.max) else None}

    @classmethod
    def from_dict(cls, d: dict) -> "RmseStats":
        out = cls()
        out.counts[np.asarray(d["bins"], dtype=np.intp)] = d["counts"]
        out.n = int(d["n"])
        out.max = -np.inf if d["max"] is None else float(d["max"])
        return out

    def quantile(self, q: float) -> float:
        """Upper edge of the 0.01-wide bin holding quantile ``q`` (capped at the max)."""
        if not self.n:
            return float("nan")
        k = int(np.searchsorted(np.cumsum(self.counts), q * self.n, side="left"))
        return float(min(self.EDGES[min(k + 1, len(self.EDGES) - 2)], self.max))


def unit_stats(res: dict, cfg: Config) -> dict:
    """The summary counts of one :func:`process_chunk` result, as plain JSON."""
    from collections import Counter

    from ..rotation import get_system

    t = res["table"]
    out_of_range = gimbal = 0
    if len(t["frame"]):
        pyr = np.stack([t["pitch"], t["yaw"], t["roll"]], axis=1)
        out_of_range = int((~get_system(cfg.system).in_range(pyr)).sum())
        gimbal = int(np.sum(t["gimbal_lock"]))
    rm = RmseStats()
    rm.add(res["fit_rmse"])
    return {"frames": res["frames"], "faces": res["faces"], "views": res["views"], "labelled": len(t["frame"]),
            "legacy_considered": res["legacy_considered"], "out_of_range": out_of_range, "gimbal": gimbal,
            "unreadable": res.get("unreadable", 0),
            "view_reasons": dict(Counter(r for r in res["rejects"]["reason"].tolist())),
            "face_reasons": dict(Counter(r for r in res["face_reasons"].tolist() if r)), "rmse": rm.to_dict()}


class Stats:
    """Counts for the end-of-run summary; every face and view is accounted for."""

    def __init__(self):
        from collections import Counter

        self.frames = self.faces = self.views = self.labelled = self.unreadable = 0
        self.legacy_considered = self.out_of_range = self.gimbal = 0
        self.view_reasons: Counter = Counter()
        self.face_reasons: Counter = Counter()
        self.rmse = RmseStats()

    def add(self, res: dict, cfg: Config) -> None:
        """Add a :func:`process_chunk` result."""
        self.add_unit(unit_stats(res, cfg))

    def add_unit(self, u: dict) -> None:
        """Add a :func:`unit_stats` dict."""
        for k in ("frames", "faces", "views", "labelled", "legacy_considered", "out_of_range", "gimbal",
                  "unreadable"):
            setattr(self, k, getattr(self, k) + int(u.get(k, 0)))
        self.view_reasons.update(u["view_reasons"])
        self.face_reasons.update(u["face_reasons"])
        self.rmse.merge(RmseStats.from_dict(u["rmse"]))

    def moved(self, reason: str, n: int) -> None:
        """``n`` labelled views were set aside by the writer (``--min-change``)."""
        if n:
            self.labelled -= n
            self.view_reasons[reason] += n

    def merge(self, other: "Stats") -> None:
        for k in ("frames", "faces", "views", "labelled", "legacy_considered", "out_of_range", "gimbal",
                  "unreadable"):
            setattr(self, k, getattr(self, k) + getattr(other, k))
        self.view_reasons.update(other.view_reasons)
        self.face_reasons.update(other.face_reasons)
        self.rmse.merge(other.rmse)

    def summary(self, p: Plan | None, cfg: Config, output, rejects_path, n_cameras: int | None = None,
                title: str | None = None) -> list:
        sysname = getattr(cfg.system, "name", cfg.system)
        if p is not None:
            nums = list(p.frames)
            span = f"{nums[0]}..{nums[-1]}" if nums else "none"
            gaps = f"; {p.missing} frame numbers on that grid have no face file" if p.missing else ""
            head = f"{p.sequence}: {self.frames} frames ({span}{gaps})"
            n_cameras = len(p.cameras)
        else:
            head = f"{title or 'total'}: {self.frames} frames"
        unread = f"; {self.unreadable} unreadable (truncated) face files" if self.unreadable else ""
        lines = [f"{head}{unread}, {self.faces} faces x {n_cameras} cameras = {self.views} views"]
        few = self.face_reasons["too few confident points"]
        broken = self.face_reasons["bad landmarks"]
        fitted = self.faces - few - broken
        gate = "off" if cfg.max_rmse is None or not np.isfinite(cfg.max_rmse) else f"{cfg.max_rmse:g}"
        lines.append(f"faces: {fitted} fitted; {few} with too few confident points; "
                     f"{self.face_reasons['bad fit']} bad fits (--max-rmse {gate})"
                     + (f"; {broken} with bad landmarks (infinite or absurd)" if broken else ""))
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


# ------------------------------------------------------------------- units
def make_units(plans: list) -> list:
    """Independent units of work: ``(sequence index, chunk index)`` in output order."""
    return [(si, ci) for si, p in enumerate(plans) for ci in range(len(p.chunks))]


def unit_task(plans: list, cfg: Config, unit: tuple, parts_dir) -> dict:
    """Everything a worker needs for one unit (small and picklable)."""
    si, ci = unit
    p = plans[si]
    return {"chunk": p.chunks[ci], "cameras": p.cameras, "sequence": p.sequence, "cfg": cfg,
            "stem": str(Path(parts_dir) / f"{si:04d}-{ci:06d}") if parts_dir is not None else None}


def run_unit(task: dict) -> dict:
    """Compute one unit and write its parts (labels and rejects as Arrow IPC
    files, then its counts as JSON, each by an atomic rename: a unit whose
    JSON exists is complete). Returns the counts; nothing big crosses processes."""
    import os

    from ..io import arrow_table

    res = process_chunk(task["chunk"], task["cameras"], task["sequence"], task["cfg"])
    stem = task["stem"]
    _write_part(f"{stem}.labels.arrow", arrow_table(res["table"]))
    _write_part(f"{stem}.rejects.arrow", arrow_table(res["rejects"], _reject_schema()))
    stats = unit_stats(res, task["cfg"])
    import json

    with open(f"{stem}.json.tmp", "w") as fh:
        json.dump(stats, fh)
    os.replace(f"{stem}.json.tmp", f"{stem}.json")
    return stats


def _read_part(path):
    import pyarrow as pa

    with pa.memory_map(str(path), "r") as src:
        return pa.ipc.open_file(src).read_all()


class MinChange:
    """``--min-change DEG``: keep a label only if its rotation differs by at least
    DEG degrees (geodesic) from the last label kept for the same (sequence,
    person, camera); labels arrive in frame order, whoever computed them."""

    def __init__(self, degrees: float):
        self.deg = float(degrees)
        self.last: dict = {}

    def apply(self, table, schema):
        import pyarrow as pa

        n = table.num_rows
        if not n:
            return table, None
        R = np.stack([table.column(f"r{i}{j}").to_numpy() for i in range(3) for j in range(3)], 1)
        seq = table.column("sequence").to_pylist()
        pid = table.column("person_id").to_numpy()
        cam = table.column("camera").to_pylist()
        frame = table.column("frame").to_numpy()
        keep = np.ones(n, dtype=bool)
        angle = np.full(n, np.nan)
        since = np.full(n, -1, dtype=np.int64)
        last = self.last
        for k in range(n):  # sequential by nature: each decision depends on the previous kept label
            key = (seq[k], int(pid[k]), cam[k])
            prev = last.get(key)
            if prev is not None:
                # geodesic angle from the Frobenius distance: |R1 - R2|_F = 2 sqrt(2) sin(theta / 2)
                d = float(np.sqrt(np.sum((R[k] - prev[0]) ** 2)))
                a = 2.0 * np.degrees(np.arcsin(min(1.0, d / (2.0 * np.sqrt(2.0)))))
                if a < self.deg:
                    keep[k] = False
                    angle[k] = a
                    since[k] = prev[1]
                    continue
            last[key] = (R[k], int(frame[k]))
        if keep.all():
            return table, None
        drop = ~keep
        t_drop = table.filter(pa.array(drop))
        rej = {"sequence": t_drop.column("sequence"), "frame": t_drop.column("frame"),
               "person_id": t_drop.column("person_id"), "camera": t_drop.column("camera"),
               "reason": pa.array(["below --min-change"] * int(drop.sum()), pa.string()),
               "detail": pa.array([f"{a:.3g} deg since frame {f}" for a, f in zip(angle[drop], since[drop])],
                                  pa.string()),
               "fit_rmse": t_drop.column("fit_rmse"), "n_pairs": t_drop.column("n_pairs"),
               "scale": t_drop.column("scale")}
        return table.filter(pa.array(keep)), pa.Table.from_pydict(rej).cast(schema)


# -------------------------------------------------------------- streaming
def _process(args: tuple) -> dict:
    return process_chunk(*args)


def run(p: Plan, cfg: Config, workers: int = 1):
    """Yield :func:`process_chunk` results for every chunk of ``p``, in order
    (in memory; :func:`write_outputs` uses parts instead)."""
    if workers <= 1 or len(p.chunks) <= 1:
        for chunk in p.chunks:
            yield process_chunk(chunk, p.cameras, p.sequence, cfg)
        return
    from .pools import in_order, unit_pool

    with unit_pool(workers, warm=WORKER_IMPORTS) as pool:
        yield from in_order(pool, _process, [(chunk, p.cameras, p.sequence, cfg) for chunk in p.chunks])


def format_unit(task: dict) -> int:
    """Format one unit's labels part as output text (COCO annotations or WHENet lines) into its text part,
    by an atomic rename; return the number of rows. Ids come with the task (the parent assigns them in order),
    so the text is the bytes the streaming writer makes for these rows."""
    import os

    t = _read_part(task["labels"])
    if task["fmt"] == "coco":
        from ..io.coco import annotations_text

        text = annotations_text(t, task["image_ids"], task["first_id"], path=task["path"], offset=task["offset"])
    else:
        from ..io.whenet_txt import whenet_text

        text = whenet_text(t, task["path"], task["offset"])
    tmp = task["text"] + ".tmp"
    with open(tmp, "wb") as fh:
        fh.write(text)
    os.replace(tmp, task["text"])
    return t.num_rows


def _fingerprint(plans: list, cfg: Config, fmt: str) -> dict:
    import hashlib

    h = hashlib.sha256()
    for p in plans:
        h.update(f"{p.sequence}|{p.calibration}|{','.join(map(str, p.cameras.names))}|".encode())
        h.update(np.fromiter(p.frames, dtype=np.int64, count=len(p.frames)).tobytes())
        h.update(str([len(c) for c in p.chunks]).encode())
    sysname = getattr(cfg.system, "name", cfg.system)
    return {"hpe_parts": 1, "format": fmt, "config": repr({**cfg.__dict__, "system": sysname,
                                                           "min_change": None}), "plans": h.hexdigest()}


def parts_dir_for(output) -> Path:
    """Where a run's parts are kept until the commit (and for ``--resume``)."""
    out = Path(output)
    return out.parent / f".{out.name}.hpe-parts"


def _prepare_parts(plans, cfg, fmt, output, resume: bool) -> Path:
    import json
    import shutil

    d = parts_dir_for(output)
    fp = _fingerprint(plans, cfg, fmt)
    run_file = d / "run.json"
    if d.exists():
        try:
            old = json.loads(run_file.read_text())
        except (OSError, ValueError):
            old = None
        if old is None or old.get("hpe_parts") != 1:
            raise HpeError(f"{d}: exists and is not an hpe parts folder; move it away")
        if resume and old != fp:
            raise HpeError(f"{d}: its parts were made with other inputs or options; run without --resume "
                           "to start over")
        if not resume:
            shutil.rmtree(d)
    d.mkdir(parents=True, exist_ok=True)
    if not run_file.exists():
        run_file.write_text(json.dumps(fp))
    return d


def write_outputs(p, cfg: Config, output, fmt: str = "table", rejects_path=None, overwrite: bool = False,
                  workers: int = 1, bar=None, *, scheduler: str | None = None, resume: bool = False,
                  per_sequence: list | None = None, pool=None) -> Stats:
    """Run the job and write its outputs atomically; return the total :class:`Stats`.

    ``p`` is one :class:`Plan` or a list of them (several sequences). The
    work is split into units (sequence x chunk of frames). With one worker,
    no ``scheduler`` and no ``resume`` the units run here and stream to the
    writers. Otherwise each unit runs in a worker (``workers`` local
    processes, or a Dask cluster at ``scheduler``, ``"local"`` for a
    ``LocalCluster``), writes its own part files next to the output, and
    returns only its counts; the parts are appended to the outputs in unit
    order (and removed as they are, unless ``resume``), so the output is
    the same bytes whoever computed it. ``resume`` keeps the parts of an
    interrupted run (same inputs and options) and computes only the missing
    units.

    ``fmt`` is ``table`` (streamed to Parquet/CSV), ``coco`` or ``whenet``
    (streamed by :class:`hpe_cli.io.coco.CocoWriter` /
    :class:`hpe_cli.io.whenet_txt.WhenetWriter`). With workers, text is
    made by the workers too: once a unit is computed, this process gives its
    rows their ids (in order: image ids by first appearance, annotation ids
    by row) and submits a second task, :func:`format_unit`, that writes the
    unit's text part; the parts are appended to the output in order (copied
    by the kernel), so the heavy float formatting runs in parallel and the
    bytes are those of the one-process run. The rejects table is streamed
    too.
    ``per_sequence``, if a list, receives one :class:`Stats` per sequence.
    ``pool``, if given, is a running :func:`worker_pool` for the same
    ``workers``, ``scheduler`` and ``resume`` (started before planning, so
    its workers are ready when the first unit is); by default the job starts
    its own.
    """
    import json
    import shutil
    from contextlib import ExitStack

    from collections import deque

    from ..io import TableWriter, arrow_table, system_metadata
    from ..rotation import get_system

    plans = p if isinstance(p, (list, tuple)) else [p]
    system = get_system(cfg.system)
    seq_stats = [Stats() for _ in plans]
    relabel = {"source": "cmu_panoptic"}
    if len(plans) == 1:
        relabel.update(sequence=plans[0].sequence, calibration=str(plans[0].calibration),
                       cameras=list(map(str, plans[0].cameras.names)))
    else:
        relabel.update(sequences=[q.sequence for q in plans], calibrations=[str(q.calibration) for q in plans],
                       cameras=[list(map(str, q.cameras.names)) for q in plans])
    relabel.update({"preset": cfg.preset,
                    "max_rmse": cfg.max_rmse if cfg.max_rmse is not None and np.isfinite(cfg.max_rmse) else None,
                    "legacy_whenet": cfg.legacy, "label": "A = E @ R_cam @ R_head, E = diag(1, -1, -1)"})
    if cfg.frame == "crop":
        relabel["label"] = "A = E @ Q.T @ R_cam @ R_head, Q: optical axis -> ray to the head centre (SPEC 10)"
    for k in ("all_views", "min_change"):
        if getattr(cfg, k):
            relabel[k] = getattr(cfg, k)
    meta = {**system_metadata(system), "hpe:relabel": json.dumps(relabel)}
    rschema = _reject_schema()
    units = make_units(plans)
    use_parts = workers > 1 or scheduler is not None or resume
    from ..io.transaction import critical, current

    parts = None
    with critical():  # a signal waits until `parts` is known and registered for cleanup
        parts = _prepare_parts(plans, cfg, fmt, output, resume) if use_parts else None
        if parts is not None and not resume and current() is not None:
            current().on_abort(lambda: shutil.rmtree(parts, ignore_errors=True))  # whatever ends the run
    tasks = [unit_task(plans, cfg, u, parts) for u in units]
    mc = MinChange(cfg.min_change) if cfg.min_change else None

    def results(pool):
        if not use_parts:
            for t in tasks:
                res = process_chunk(t["chunk"], t["cameras"], t["sequence"], t["cfg"])
                yield unit_stats(res, cfg), arrow_table(res["table"]), arrow_table(res["rejects"], rschema)
            return
        from .pools import in_order

        todo = [t for t in tasks if not Path(t["stem"] + ".json").exists()]
        computed = in_order(pool, run_unit, todo)
        need = {t["stem"] for t in todo}
        for t in tasks:
            stem = t["stem"]
            if stem in need:
                next(computed)  # in order: this unit's parts are complete after it
            stats = json.loads(Path(stem + ".json").read_text())
            yield stats, _read_part(stem + ".labels.arrow"), _read_part(stem + ".rejects.arrow")

    def drop_parts(stem):  # a consumed unit's parts, unless they are kept for --resume
        if not resume:
            for suffix in (".labels.arrow", ".rejects.arrow", ".json", ".kept.arrow"):
                Path(stem + suffix).unlink(missing_ok=True)

    text_parts = use_parts and fmt != "table"
    formatting: deque = deque()  # (future, text part, rows, stem) in output order

    def append_formatted(limit):
        """Append the formatted units at the head of the queue: all that are done, and more while over limit."""
        while formatting and (len(formatting) > limit or formatting[0][0].done()):
            fut, text, rows, stem = formatting.popleft()
            fut.result()
            out.append_file(text, rows)  # opened before it returns: the part can go at once
            Path(text).unlink(missing_ok=True)
            drop_parts(stem)

    from .pools import borrow

    try:
        with ExitStack() as stack:
            # the pool first: its workers start (and import what a unit needs) while the writers are set up
            pool = stack.enter_context(borrow(pool) if pool is not None else
                                       worker_pool(workers, scheduler, resume))
            if fmt == "table":
                out = stack.enter_context(TableWriter(output, overwrite, meta))
            else:
                out = stack.enter_context(_text_writer(fmt, output, overwrite, meta.get("hpe:system")))
            rej = stack.enter_context(TableWriter(rejects_path, overwrite)) if rejects_path else None
            ahead = 2 * getattr(pool, "workers", 1)
            registered = 0  # rows given ids so far (text formats on parts)
            for (si, _), task, (stats, t, r) in zip(units, tasks, results(pool)):
                seq_stats[si].add_unit(stats)
                kept = None
                if mc is not None:
                    t, moved = mc.apply(t, rschema)
                    if moved is not None:
                        seq_stats[si].moved("below --min-change", moved.num_rows)
                        import pyarrow as pa

                        r = pa.concat_tables([r, moved])
                        kept = t
                if rej is not None:
                    rej.write(r)
                if text_parts:  # ids here, in order; the text is made by a worker
                    stem = task["stem"]
                    labels = stem + ".labels.arrow"
                    if kept is not None:  # --min-change dropped rows: the worker formats what is kept
                        labels = stem + ".kept.arrow"
                        _write_part(labels, kept)
                    job2 = {"fmt": fmt, "labels": labels, "text": f"{stem}.{fmt}.text", "path": str(output),
                            "offset": registered, "first_id": registered + 1,
                            "image_ids": out.image_ids(t, registered) if fmt == "coco" else None}
                    registered += t.num_rows
                    formatting.append((pool.submit(format_unit, job2), job2["text"], t.num_rows, stem))
                    append_formatted(ahead)
                else:
                    out.write(t)
                    if use_parts:
                        drop_parts(task["stem"])
                if bar is not None:
                    bar.update(stats["frames"])
            append_formatted(0)
    except BaseException:
        # an interrupted run keeps its parts only when it was asked to be resumable (--resume);
        # otherwise nothing of it is left behind (the output transaction's promise)
        if parts is not None and not resume:
            shutil.rmtree(parts, ignore_errors=True)
        raise
    if parts is not None:
        shutil.rmtree(parts, ignore_errors=True)
    total = Stats()
    for st in seq_stats:
        total.merge(st)
    if per_sequence is not None:
        per_sequence.extend(seq_stats)
    return total


#: what a unit imports on its first run: local workers import it as they start, while the parent prepares the
#: job (a unit builds its Arrow arrays from numpy buffers, so pandas, 0.3 s to import, is never needed)
WORKER_IMPORTS = ("pyarrow.compute", "pyarrow.ipc", "hpe_cli.io", "hpe_cli.io.coco", "orjson")


def worker_pool(workers: int = 1, scheduler: str | None = None, resume: bool = False):
    """The pool :func:`write_outputs` runs its units on for these options (a context manager): ``workers``
    local processes, a Dask cluster at ``scheduler``, or this process (one worker, no scheduler, no
    ``resume``). Start it before planning and pass it as ``pool=``: the workers start and import what a
    unit needs meanwhile."""
    from .pools import unit_pool

    use_parts = workers > 1 or scheduler is not None or resume
    return unit_pool(workers if use_parts else 1, scheduler if use_parts else None, warm=WORKER_IMPORTS)


def _text_writer(fmt: str, output, overwrite: bool, system=None):
    """The streaming COCO or WHENet writer (flat memory; units formatted elsewhere are appended as files)."""
    if fmt == "coco":
        from ..io.coco import CocoWriter

        return CocoWriter(output, overwrite, image_size_cols=("image_width", "image_height"),
                          info={"hpe:system": system} if system else None)  # read back by io.system_meta
    from ..io.whenet_txt import WhenetWriter

    return WhenetWriter(output, overwrite)


def _write_part(path, table) -> None:
    """An Arrow IPC part file, by an atomic rename (a part that exists is complete)."""
    import os

    import pyarrow as pa

    tmp = f"{path}.tmp"
    with pa.OSFile(tmp, "wb") as sink, pa.ipc.new_file(sink, table.schema) as w:
        w.write_table(table)
    os.replace(tmp, path)


__all__ = ["Config", "Plan", "plan", "plan_many", "find_sequences", "process_chunk", "run", "run_unit",
           "write_outputs", "parse_frames", "Stats", "RmseStats", "MinChange", "REASONS", "CHUNK_FRAMES",
           "LEGACY_COLS", "REJECT_COLS", "WHENET_HAGGLING", "CAMERA_PRESETS", "parts_dir_for", "format_unit",
           "worker_pool"]
