"""AGORA relabelling (DirectMHP's method, corrected; SPEC §7).

For every person of every ``*_withjv.pkl`` dataframe: skip the occluded
(``occlusion >= 90``) and the invalid, fit WHENet's reference head to the 13
face joints DirectMHP pairs with it (one batched similarity fit), gate on the
fit residual, label ``A = E @ camR @ R_head`` in any rotation system, and
box the head with DirectMHP's helmet (radius 18, aspect < 1.5, each side < 70%
of the image). Every person that gets no label is a reject with a reason.
Everything is vectorised over the people of a dataframe; dataframes are
processed one at a time so memory stays bounded by the largest one.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from ...datasets import agora as ag
from ...errors import HpeError
from ...geometry.reference import agora_pairs
from ...io import TableWriter, arrow_table, system_metadata
from ...io.coco import CocoWriter
from ...io.rejects import rejects_rule
from ...io.whenet_txt import WhenetWriter
from ..pools import library_threads, run_in_order
from .core import LEGACY_COLS, fit_faces, relabel_views, summary_tail, view_label_columns

#: default fit-quality gate in the landmarks' unit (metres for AGORA): 2 cm, the Panoptic gate
DEFAULT_MAX_RMSE = 0.02
#: DirectMHP keeps people with occlusion < 90 (percent)
DEFAULT_MAX_OCCLUSION = 90.0
REASON_ORDER = (
    "bad input",
    "occluded",
    "invalid",
    "too few confident points",
    "bad fit",
    "behind camera",
    "outside image",
    "box rejected",
    "dropped by legacy rule",
)


@dataclass
class Config:
    """What to compute (everything but I/O)."""

    system: object = "300w_lp"
    image_size: tuple = ag.AGORA_SIZE
    max_rmse: float | None = DEFAULT_MAX_RMSE
    max_occlusion: float = DEFAULT_MAX_OCCLUSION
    legacy: bool = False
    preset: str = "directmhp"
    frame: str = "camera"  # "camera" or "crop" (line of sight to the helmet centre, SPEC §10)
    trust_pickle: bool = False


def relabel_people(people: ag.AgoraPeople, cfg: Config) -> dict:
    """Label every person of one dataframe.

    Returns
    -------
    dict
        ``table``: output columns of the labelled people (dataframe order);
        ``rejects``: reject columns (one row per person not labelled, with
        ``reason`` and ``detail``); ``fit_rmse``: RMSE of the fitted faces;
        ``legacy_considered``: people that reached WHENet's rule.
    """

    n = len(people)
    W, H = (int(v) for v in cfg.image_size)
    K, factor = ag.intrinsics_for_size(people, W, H)
    fit = fit_faces(people.face3d, None, agora_pairs(), max_rmse=cfg.max_rmse)
    occ = people.occlusion
    with np.errstate(invalid="ignore"):
        occluded = ~(occ < cfg.max_occlusion)  # NaN (unknown) counts as occluded
    invalid = ~people.valid & ~occluded
    fit["reason"][invalid] = "invalid"
    fit["detail"][invalid] = "isValid is False"
    fit["reason"][occluded] = "occluded"
    fit["detail"][occluded] = [f"occlusion {o:g}% not < {cfg.max_occlusion:g}%" for o in occ[occluded]]
    door = getattr(people, "reason", None)  # validated at the door (datasets/agora.py)
    if door is not None and (door != "").any():
        fit["reason"][door != ""] = "bad input"
        fit["detail"][door != ""] = door[door != ""]
    cam = {
        "K": K,
        "dist": np.zeros((n, 5)),
        "R": people.cam_R,
        "t": people.cam_t,
        "width": np.full(n, float(W)),
        "height": np.full(n, float(H)),
    }
    # rows without a fit carry NaN through the projection; their reason is already set
    with np.errstate(invalid="ignore", divide="ignore"):
        v = relabel_views(
            fit,
            np.arange(n),
            cam,
            cfg.system,
            preset=cfg.preset,
            legacy=cfg.legacy,
            landmarks=people.face3d,
            frame=cfg.frame,
        )
    ok = v["ok"]
    source = people.source.name
    table = {
        "source": np.full(int(ok.sum()), source, dtype=object),
        "row": people.row[ok],
        "person": people.person[ok],
        "image": people.image[ok],
    }
    table.update(view_label_columns(v, fit, np.flatnonzero(ok), cfg.legacy))
    table["occlusion"] = occ[ok]
    table["image_width"] = np.full(int(ok.sum()), W, dtype=np.int64)
    table["image_height"] = np.full(int(ok.sum()), H, dtype=np.int64)
    bad = ~ok
    rejects = {
        "source": np.full(int(bad.sum()), source, dtype=object),
        "row": people.row[bad],
        "person": people.person[bad],
        "image": people.image[bad],
        "reason": v["reason"][bad],
        "detail": v["detail"][bad],
        "occlusion": occ[bad],
        "isValid": people.valid[bad],
        "fit_rmse": fit["rmse"][bad],
        "n_pairs": fit["n_pairs"][bad],
        "scale": fit["scale"][bad],
    }
    considered = int(np.isin(v["reason"], ("", "dropped by legacy rule")).sum()) if cfg.legacy else 0
    fitted = np.isfinite(fit["rmse"]) & ~occluded & ~invalid
    return {
        "table": table,
        "rejects": rejects,
        "fit_rmse": fit["rmse"][fitted],
        "legacy_considered": considered,
        "people": n,
        "images": people.images,
        "frame": people.frame,
        "k_scale": factor,
    }


class Stats:
    """Counts for the end-of-run summary; every person is accounted for."""

    def __init__(self):
        self.files = self.images = self.people = self.labelled = 0
        self.legacy_considered = self.out_of_range = self.gimbal = 0
        self.reasons: Counter = Counter()
        self.rmse: list = []
        self.per_file: list = []

    def add(self, path, res: dict, system) -> None:
        t = res["table"]
        self.files += 1
        self.images += res["images"]
        self.people += res["people"]
        self.labelled += len(t["row"])
        self.reasons.update(res["rejects"]["reason"].tolist())
        self.rmse.append(res["fit_rmse"])
        self.legacy_considered += res["legacy_considered"]
        if len(t["row"]):
            pyr = np.stack([t["pitch"], t["yaw"], t["roll"]], axis=1)
            self.out_of_range += int((~system.in_range(pyr)).sum())
            self.gimbal += int(np.sum(t["gimbal_lock"]))
        ks = np.unique(np.round(res["k_scale"], 6), axis=0) if len(res["k_scale"]) else np.zeros((0, 2))
        scaled = (
            ""
            if res["frame"] == "camera" or not len(ks) or np.allclose(ks, 1.0)
            else f"; camK rescaled by {', '.join(f'{a:g}' for a in np.unique(ks[:, 0]))}"
        )
        frame = (
            "camera frame (gt_joints_3d, AGORA's intrinsics)"
            if res["frame"] == "camera"
            else "body frame (cam_j3d, camR, camT, camK)"
        )
        self.per_file.append(
            f"{path}: {res['images']} images, {res['people']} people, {len(t['row'])} labelled; {frame}{scaled}"
        )

    def summary(self, cfg: Config, output, rejects_path, verbose: int = 0) -> list:
        sysname = getattr(cfg.system, "name", cfg.system)
        lines = list(self.per_file) if verbose else []
        lines.append(
            f"{self.people} people in {self.images} images from {self.files} dataframe"
            f"{'s' if self.files != 1 else ''} (image size {cfg.image_size[0]}x{cfg.image_size[1]})"
        )
        rmse = np.concatenate(self.rmse) if self.rmse else np.zeros(0)
        if rmse.size:
            q = np.quantile(rmse, [0.5, 0.95])
            gate = "off" if cfg.max_rmse is None or not np.isfinite(cfg.max_rmse) else f"{100 * cfg.max_rmse:g}"
            lines.append(
                f"fit RMSE (cm) of {rmse.size} fitted faces: median {100 * q[0]:.2f}, p95 {100 * q[1]:.2f}, "
                f"max {100 * rmse.max():.2f} (--max-rmse {gate})"
            )  # the option is in cm, as in Panoptic
        pct = 100.0 * self.labelled / self.people if self.people else 0.0
        lines.append(f"labelled {self.labelled} of {self.people} people ({pct:.1f}%) in {sysname} -> {output}")
        rej = sum(self.reasons.values())
        if rej:
            order = {r: k for k, r in enumerate(REASON_ORDER)}
            parts = "; ".join(f"{self.reasons[r]} {r}" for r in sorted(self.reasons, key=lambda r: order.get(r, 99)))
            lines.append(f"not labelled {rej}: {parts}" + (f" -> {rejects_path}" if rejects_path else ""))
        lines += summary_tail(
            cfg.legacy,
            self.reasons["dropped by legacy rule"],
            self.legacy_considered,
            self.out_of_range,
            self.gimbal,
            sysname,
            "people",
            "DirectMHP",
        )
        return lines


def check_inputs(paths) -> None:
    """Refuse a dataframe given twice (same file by inode, also through another path or a link) and two
    dataframes with the same file name (the ``source`` column holds the name, so their people would have
    the same keys ``source, row, person``): one line naming both."""
    by_inode: dict = {}
    by_name: dict = {}
    for p in paths:
        try:
            st = os.stat(p)
        except OSError as exc:
            raise HpeError(f"{p}: cannot read ({exc.strerror or exc})") from None
        ident = (st.st_dev, st.st_ino)
        if ident in by_inode:
            raise HpeError(
                f"{by_inode[ident]} and {p}: the same dataframe given twice (its people would be "
                "labelled twice, with the same keys); give it once"
            )
        by_inode[ident] = p
        name = os.path.basename(os.fspath(p))
        if name in by_name:
            raise HpeError(
                f"{by_name[name]} and {p}: two dataframes named {name!r}; the output's source column "
                "holds the file name, so their people would have the same keys (source, row, person); "
                "rename one"
            )
        by_name[name] = p


def bad_input_rule(people: ag.AgoraPeople) -> None:
    """Without a rejects file, a person whose fields are invalid (camera, joints, image path, occlusion:
    :attr:`AgoraPeople.reason`) is an error naming the file, row, person and field, as for every reader."""
    bad = np.flatnonzero(people.reason != "") if people.reason is not None else []
    if len(bad):
        k = int(bad[0])
        raise HpeError(
            f"{people.source}: row {people.row[k]}, person {people.person[k]}: {people.reason[k]}; "
            f"{len(bad)} person(s) with invalid input: nothing written (use --rejects FILE to set "
            "them aside and write the rest)"
        )


def _reject_schema():
    return pa.schema(
        [
            ("source", pa.string()),
            ("row", pa.int64()),
            ("person", pa.int64()),
            ("image", pa.string()),
            ("reason", pa.string()),
            ("detail", pa.string()),
            ("occlusion", pa.float64()),
            ("isValid", pa.bool_()),
            ("fit_rmse", pa.float64()),
            ("n_pairs", pa.int64()),
            ("scale", pa.float64()),
        ]
    )


def run_relabel_agora(paths, output, opts, *, progress=None) -> Stats:
    """Relabel the AGORA dataframes ``paths`` into ``output`` with the settings ``opts``
    (:class:`~.options.RelabelAgoraOptions`); ``progress(total=files)``, if given, makes the progress bar.
    With ``opts.strict`` any person not labelled fails the run (nothing is committed). Returns the counts."""
    paths = list(paths)
    bar = progress(total=len(paths)) if progress is not None else None
    try:
        stats = write_outputs(paths, output, opts, bar=bar)
    finally:
        if bar is not None:
            bar.close()
    if opts.strict:  # any person not labelled fails the run (nothing is committed)
        rejects_rule(sum(stats.reasons.values()), next(iter(stats.reasons), None), has_file=True, strict=True)
    return stats


def relabel_about(paths, cfg: Config) -> dict:
    """The ``hpe:relabel`` record of the output: the dataframes and the settings."""
    return {
        "source": "agora",
        "dataframes": [str(p) for p in paths],
        "preset": cfg.preset,
        "image_size": list(cfg.image_size),
        "max_occlusion": cfg.max_occlusion,
        "max_rmse_m": cfg.max_rmse if cfg.max_rmse is not None and np.isfinite(cfg.max_rmse) else None,
        "legacy_whenet": cfg.legacy,
        "label": "A = E @ camR @ R_head, E = diag(1, -1, -1)"
        if cfg.frame == "camera"
        else "A = E @ Q.T @ camR @ R_head, Q: optical axis -> ray to the head centre (SPEC 10)",
    }


def _label_writer(fmt: str, output, overwrite: bool, system, about: dict):
    """The streaming writer of the labels: a table, DirectMHP's COCO JSON or WHENet's annotation.txt."""
    if fmt == "table":
        return TableWriter(output, overwrite, {**system_metadata(system), "hpe:relabel": json.dumps(about)})
    if fmt == "coco":  # streamed: memory flat in the number of people
        info = {
            "description": "AGORA head-pose labels (hpe relabel-agora)",
            "hpe:system": system.name,
            "hpe:relabel": about,
        }
        return CocoWriter(output, overwrite, info=info)
    if fmt == "whenet":
        return WhenetWriter(output, overwrite)
    raise HpeError(f"expected --format table, coco or whenet, got {fmt!r}")


def write_outputs(paths, output, opts, *, bar=None) -> Stats:
    """Relabel every dataframe of ``paths`` and write the outputs atomically.

    ``opts.fmt`` is ``table`` (Parquet/CSV), ``coco`` (:class:`hpe_cli.io.coco.CocoWriter`) or ``whenet``
    (:class:`hpe_cli.io.whenet_txt.WhenetWriter`), each streamed one dataframe at a time. Outputs are checked
    before any work, and nothing is left behind on failure. The dataframes are read and fitted on
    ``opts.threads`` threads (at most one more than that in memory) and written in input order, with OpenCV's
    and pyarrow's pools limited to as many (:func:`~hpe_cli.pipelines.pools.library_threads`).
    """
    cfg = opts.config()
    system = cfg.system
    stats = Stats()
    about = relabel_about(paths, cfg)
    rschema = _reject_schema()
    check_inputs(paths)

    def work(path):
        people = ag.read_agora(path, trust=cfg.trust_pickle)
        if not opts.rejects:
            bad_input_rule(people)
        return relabel_people(people, cfg)

    with ExitStack() as stack:
        threads = stack.enter_context(library_threads(opts.threads))
        out = stack.enter_context(_label_writer(opts.fmt, output, opts.overwrite, system, about))
        rej = stack.enter_context(TableWriter(opts.rejects, opts.overwrite)) if opts.rejects else None

        def finish(path, res):
            stats.add(path, res, system)
            out.write(arrow_table(res["table"]))
            if rej is not None:
                rej.write(arrow_table(res["rejects"], rschema))
            if bar is not None:
                bar.update(1)

        run_in_order(((p,) for p in paths), work, finish, threads)
    return stats


__all__ = [
    "Config",
    "Stats",
    "relabel_people",
    "run_relabel_agora",
    "write_outputs",
    "check_inputs",
    "bad_input_rule",
    "DEFAULT_MAX_RMSE",
    "DEFAULT_MAX_OCCLUSION",
    "LEGACY_COLS",
    "REASON_ORDER",
]
