"""Export stage 2, select and split: labels in the layout's system, the layout's own rules, the split, the
sampling rules (``--min-change``, ``--balance``, ``--drop-images-with-rejects``). Every row a rule skips gets
the rule's reason (it becomes a reject); nothing is dropped silently."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import HpeError
from ...io.exclude import ExcludeList
from ...io.layout import landmark_count
from ...rotation.convert import canonical_to_labels
from .options import A_COLS
from .sampling import assign_splits, balance_keep, min_change_keep, parse_balance, parse_split, read_split_file

GROUP_COLUMNS = "sequence, subject, identity, person_id, camera, source, image"


@dataclass
class Selection:
    """The label table after stage 2: one entry per input row (rejects keep their reason)."""

    rows: object
    reasons: np.ndarray
    A: np.ndarray
    conv: object
    ang: np.ndarray
    lm: np.ndarray
    split: np.ndarray
    notes: list = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.reasons)


def label_stage(rows, layout, system) -> Selection:
    """Labels in ``system`` (through the matrices) and the layout's own label rules."""

    n = len(rows)
    reasons = rows["reason"].to_numpy(dtype=object).copy()
    A = rows[A_COLS].to_numpy(np.float64).reshape(n, 3, 3)
    conv = canonical_to_labels(A, system)
    ang = conv.primary
    ok = reasons == ""
    rule = layout.label_reasons(ang)
    reasons[ok & (rule != "")] = rule[ok & (rule != "")]
    n_lm = landmark_count(rows.columns)
    lm = (
        np.stack([rows[[f"lm{i}_{a}" for i in range(n_lm)]].to_numpy(np.float64) for a in "xy"], -1)
        if n_lm
        else np.full((n, 0, 2), np.nan)
    )
    if layout.needs_landmarks:
        nolm = ~np.isfinite(lm).all(-1).any(1) if n_lm else np.ones(n, bool)
        reasons[(reasons == "") & nolm] = "no 2-D landmarks (the 6DRepNet .mat loader crops from pt2d)"
    return Selection(rows, reasons, A, conv, ang, lm, np.full(n, "train", dtype=object))


def split_stage(sel: Selection, layout, opts) -> None:
    """``--split-file``, ``--split`` or the layout's default split; rows a split file does not list are rejects."""
    import pandas as pd

    rows, reasons = sel.rows, sel.reasons
    if opts.split and opts.split_file:
        raise HpeError("use --split or --split-file, not both")
    if opts.split_file:
        col, mapping = read_split_file(opts.split_file)
        if col not in rows.columns:
            raise HpeError(
                f"{opts.split_file}: group column {col!r} is not in the labels (expected one of {GROUP_COLUMNS})"
            )
        split = rows[col].astype(str).map(mapping).to_numpy(dtype=object)
        miss = pd.isna(split)
        reasons[(reasons == "") & miss] = f"{col} not listed in --split-file"
        split = np.where(miss, "", split).astype(object)
    elif opts.split:
        col, names, fr = parse_split(opts.split)
        if col not in rows.columns:
            raise HpeError(f"--split: column {col!r} is not in the labels (expected one of {GROUP_COLUMNS})")
        split = assign_splits(rows[col].astype(str).to_numpy(), names, fr, opts.seed)
    else:
        split = layout.default_splits(rows)
        if split is None:
            split = np.full(sel.n, "train", dtype=object)
    sel.rows = rows.copy()
    sel.rows["split"] = split
    sel.split = split


def sampling_stage(sel: Selection, system, opts) -> list:
    """``--min-change``, ``--balance``, ``--drop-images-with-rejects``; returns the notes for the summary."""
    rows, reasons = sel.rows, sel.reasons
    notes = []
    if opts.min_change is not None:
        keys = (
            rows["source"].astype(str)
            + "\0"
            + rows["sequence"].astype(str)
            + "\0"
            + rows["person_id"].astype(str)
            + "\0"
            + rows["camera"].astype(str)
        ).to_numpy()
        ok = reasons == ""
        keep = min_change_keep(keys, rows["frame"].to_numpy(), sel.A, opts.min_change, ok)
        reasons[ok & ~keep] = f"min-change: within {opts.min_change:g} deg of the last kept sample"
        notes.append(
            f"--min-change {opts.min_change:g}: per (sequence, person, camera), in frame order, a sample "
            f"is kept only if its rotation differs from the last kept one by more than {opts.min_change:g} "
            "degrees (geodesic angle)"
        )
    if opts.balance:
        bin_deg, mx = parse_balance(opts.balance)
        ok = reasons == ""
        keep, bins = balance_keep(sel.ang[:, 1], bin_deg, mx, ok, opts.seed)
        lo = -180.0 + bins * bin_deg
        drop = ok & ~keep
        reasons[drop] = [f"balance: yaw bin [{a:g}, {a + bin_deg:g}) over {mx}" for a in lo[drop]]
        notes.append(
            f"--balance yaw:{bin_deg:g}:{mx} --seed {opts.seed}: at most {mx} samples per {bin_deg:g}-degree "
            f"bin of {system.name} yaw, chosen at random with seed {opts.seed}"
        )
    if opts.drop_images_with_rejects:
        img_key = (rows["source"].astype(str) + "\0" + rows["image"].astype(str)).to_numpy()
        bad_imgs = np.unique(img_key[reasons != ""])
        hit = (reasons == "") & np.isin(img_key, bad_imgs)
        reasons[hit] = "image dropped: another head in it has no label (--drop-images-with-rejects)"
        notes.append("--drop-images-with-rejects: an image is exported only if every head in it is")
    sel.notes = notes
    return notes


def select(rows, layout, system, opts) -> Selection:
    """Stage 2 as a whole: labels and layout rules, split, sampling."""
    sel = label_stage(rows, layout, system)
    if opts.exclude:  # --exclude: a key list (hpe audit --suspects); a choice, like the split file
        why = ExcludeList(opts.exclude).reasons_frame(rows)
        hit = (why != "") & (sel.reasons == "")
        sel.reasons[hit] = why[hit]
    split_stage(sel, layout, opts)
    opts.sampling_notes = sampling_stage(sel, system, opts)
    return sel
