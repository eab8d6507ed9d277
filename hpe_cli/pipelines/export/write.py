"""Export stage 4, write the layout: the staging folder, the exported rows handed to the layout, ``crops.csv``,
the dataset card, ``export.json`` and the rejects (every input row not exported, with its reason)."""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ...errors import HpeError
from ...io.layout import BBOX_COLS
from ...io.rejects import fail_all_rejected, rejects_rule
from ...io.table_source import row_name
from ...io.transaction import current
from ...io.transaction import staged_dir as shared
from .options import LICENCES, MATRIX_COLS
from .sampling import is_choice
from .workers import unspill


@contextmanager
def staged_dir(path, overwrite: bool):
    """A temporary folder that becomes ``path`` when the run commits (``hpe_cli.io.transaction.staged_dir``).

    An export replaces a whole dataset: with ``overwrite``, files of an earlier export that this one did not
    write are removed after the commit (a stale shard or split folder would otherwise be read with the new
    ones).
    """

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise HpeError(f"{path}: exists and is not a folder")
    if path.exists() and not overwrite:
        raise HpeError(f"{path}: already exists (use --overwrite to replace it)")
    with shared(path, overwrite) as tmp:
        tmp = Path(tmp)
        yield tmp
        if path.is_dir():
            keep = {p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file()}
            txn = current()

            def prune():
                for p in sorted(path.rglob("*"), key=lambda q: len(q.parts), reverse=True):
                    rel = p.relative_to(path)
                    if p.is_file() or p.is_symlink():
                        if rel not in keep:
                            p.unlink(missing_ok=True)
                    elif p.is_dir() and not any(p.iterdir()):
                        p.rmdir()

            if txn is not None:
                txn.after_commit(prune)


def add_pixels(layout, sel, plan, px, good, payloads, spill_fh) -> None:
    """Hand one slice of finished heads (and their pixels) to the layout, split by split."""
    split = sel.split
    g = np.asarray(good)
    for s in sorted(set(split[g].tolist())):
        sel_k = [k for k, gi in enumerate(good) if split[gi] == s]
        sub = exported_frame(sel, plan, px, g[sel_k])
        layout.add_pixels(s, sub, [unspill(payloads[k], spill_fh) for k in sel_k])


def exported_frame(sel, plan, px, idx):
    """The exported rows' metadata: labels in the layout system, boxes, crop box, sizes, landmarks."""
    import pandas as pd

    rows, ang, lm = sel.rows, sel.ang, sel.lm
    idx = np.asarray(idx, dtype=np.int64)
    sub = rows.iloc[idx]
    d = {
        c: sub[c].to_numpy()
        for c in ["split", "source", "kind", "image", "sequence", "camera", "frame", "person_id", "subject"] + BBOX_COLS
    }
    d["file"] = plan.rel[idx]
    d["pitch"], d["yaw"], d["roll"] = ang[idx, 0], ang[idx, 1], ang[idx, 2]
    M = sel.conv.matrix[idx].reshape(-1, 9)
    for k, c in enumerate(MATRIX_COLS):
        d[c] = M[:, k]
    for k, c in enumerate(["crop_x0", "crop_y0", "crop_x1", "crop_y1"]):
        d[c] = plan.pbox[idx, k]
    d["out_w"], d["out_h"] = plan.osz[idx, 0], plan.osz[idx, 1]
    d["image_width"], d["image_height"] = px.W[idx], px.H[idx]
    for c in ("tdx", "tdy", "tdz", "scale"):
        if c in rows.columns:
            d[c] = sub[c].to_numpy(np.float64)
    for i in range(lm.shape[1]):
        d[f"lm{i}_x"], d[f"lm{i}_y"] = lm[idx, i, 0], lm[idx, i, 1]
    return pd.DataFrame(d)


CROP_COLUMNS = [
    "split",
    "file",
    "source",
    "image",
    "bbox_x",
    "bbox_y",
    "bbox_w",
    "bbox_h",
    "crop_x0",
    "crop_y0",
    "crop_x1",
    "crop_y1",
    "out_w",
    "out_h",
    "image_width",
    "image_height",
]


def write_index(stage, layout, sel, plan, px, todo, system, final_root):
    """The layout's index files, ``crops.csv`` and (hf) the card; returns (exported frame, layout notes)."""
    done = np.flatnonzero((sel.reasons == "") & (px.order >= 0))
    done = done[np.argsort(px.order[done], kind="stable")]
    if done.size == 0:
        raise nothing_left(layout, sel.reasons, todo, "no label could be exported")
    exported = exported_frame(sel, plan, px, done)
    try:  # a split whose every image was unreadable is gone: check again what the trainer needs
        layout.check_splits(sorted(set(exported["split"].tolist())))
    except ValueError as exc:
        raise HpeError(str(exc)) from None
    notes_extra = layout.finish(exported, final_root)
    if not layout.full_frames:
        # every crop's box in the source frame's pixels (exclusive ends) and its written size
        exported[CROP_COLUMNS].to_csv(stage / "crops.csv", index=False)
    if layout.writes_card:
        kinds = sorted(set(sel.rows["kind"].iloc[done].tolist()))
        layout.write_card(
            exported, system, sel.notes, {k: LICENCES.get(k, LICENCES["table"]) for k in kinds}, final_root
        )
    return exported, notes_extra


def summary_of(layout, system, inputs, sel, plan, exported, notes_extra, opts) -> dict:
    """The ``export.json`` summary."""
    import pandas as pd

    reasons = sel.reasons
    per_reason = pd.Series(reasons[reasons != ""]).value_counts().to_dict()
    per_split = exported["split"].value_counts().sort_index().to_dict()
    return {
        "layout": layout.name,
        "form": getattr(layout, "form", None),
        "trainer": layout.trainer,
        "read_by": layout.loader,
        "system": system.name,
        "system_description": system.describe(),
        "inputs": [str(p) for p in inputs],
        "labels": int(sel.n),
        "exported": len(exported),
        "per_split": per_split,
        "rejected": int((reasons != "").sum()),
        "rejects_per_reason": per_reason,
        "sampling": sel.notes,
        "crop": {
            "scale": plan.scale,
            "square": bool(plan.square),
            "size": None if plan.size is None else int(plan.size),
            "jpeg_quality": int(opts.quality),
            "pad_value": int(opts.pad_value),
            "min_inside": opts.min_inside,
        },
        "split": opts.split or (opts.split_file and f"file {opts.split_file}") or layout.default_split_note,
        "seed": opts.seed,
        "notes": notes_extra,
    }


def where(rows, k: int, reason: str) -> str:
    """``FILE: row N: reason`` for a table row, ``FOLDER/NAME.mat: reason`` for a one-record ``.mat`` label; an
    image fault also names the image."""

    inp, row = str(rows["input"].iat[k]), str(rows["row"].iat[k])
    head = f"{Path(inp) / row}" if row.lower().endswith(".mat") else row_name(inp, row)  # line N / row N
    image = str(rows["image"].iat[k])
    if reason.startswith(("no image", "unreadable image")) and image:
        return f"{head}: {reason}: {Path(str(rows['root'].iat[k])) / image}"
    return f"{head}: {reason}"


def write_rejects(rejects, sel, opts) -> None:
    """Every input label not exported, with its reason; bad input follows the ``--rejects``/``--strict`` rule.

    Bad input (unusable rows, missing/unreadable images, boxes outside the frame) follows the rule of every
    command: without ``--rejects`` (or with ``--strict``) it is an error and nothing is written; the layout's own
    rules, the sampling and the split file are choices, always counted in the summary.
    """
    _add_rejects(rejects, sel)
    rows, reasons = sel.rows, sel.reasons
    bad = np.flatnonzero((reasons != "") & ~np.array([is_choice(r) for r in reasons], dtype=bool))
    if bad.size:
        k = int(bad[0])
        rejects_rule(
            int(bad.size), where(rows, k, str(reasons[k])), has_file=rejects.path is not None, strict=opts.strict
        )
    if opts.strict and (reasons != "").any():
        k = int(np.flatnonzero(reasons != "")[0])
        raise HpeError(
            f"{where(rows, k, str(reasons[k]))}; "
            f"{int((reasons != '').sum())} label(s) not exported and --strict given: nothing written"
        )
    rejects.write()


def _add_rejects(rejects, sel) -> None:
    """Every label not exported, with its reason, added to ``rejects``."""
    rows, reasons = sel.rows, sel.reasons
    rej = np.flatnonzero(reasons != "")
    if rej.size:
        sub = rows.iloc[rej]
        if rejects.first_where is None:  # rows of a .mat folder are file names, not numbers
            rejects.first_where = where(rows, int(rej[0]), str(reasons[rej[0]]))
        rejects.add(
            {
                "input": sub["input"].to_numpy(),
                "row": sub["row"].astype(str).to_numpy(),
                "source": sub["source"].to_numpy(),
                "image": sub["image"].to_numpy(),
                "sequence": sub["sequence"].to_numpy(),
                "camera": sub["camera"].to_numpy(),
                "frame": sub["frame"].to_numpy(),
                "person_id": sub["person_id"].to_numpy(),
                "split": rows["split"].to_numpy()[rej].astype(str),
            },
            reasons[rej],
        )


def write_summary(stage, summary) -> None:
    with open(stage / "export.json", "w", encoding="utf-8") as fh:
        json.dump(summary, fh, indent=1, default=str)


class NothingLeft(HpeError):
    """Every label was rejected: nothing to export (:func:`fail_nothing_left` still writes the rejects file)."""


def nothing_left(layout, reasons, idx, what: str) -> HpeError:
    """The error for a run where every label of ``idx`` is rejected."""
    import pandas as pd

    c = pd.Series(reasons[idx]).value_counts()
    return NothingLeft(
        f"--layout {layout.name}: {what}, nothing written ({'; '.join(f'{r}: {k}' for r, k in c.items())})"
    )


def fail_nothing_left(rejects, sel, err: HpeError, strict: bool):
    """Raise ``err`` (every label rejected). With ``--rejects`` and no ``--strict`` the rejects file is still
    written, every label with its reason (the one output that says why); the export itself is not."""

    if rejects.path is None or strict:
        raise err
    _add_rejects(rejects, sel)
    fail_all_rejected(rejects, str(err))
