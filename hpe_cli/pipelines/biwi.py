"""``hpe biwi``: BIWI labels in the depth or RGB camera, with head boxes, a protocol subset and sequence splits."""

from __future__ import annotations

from pathlib import Path


def run_biwi(
    input_path,
    output,
    *,
    camera="depth",
    calibration=None,
    head_size=200.0,
    system="biwi",
    protocol="all",
    split=None,
    seed=0,
    split_lists=None,
    overwrite=False,
    rejects_path=None,
    strict=False,
) -> dict:
    """Read BIWI, write the label table (and the split's sequence lists); return a summary dict.

    A frame whose pose file is unreadable or invalid goes to ``rejects_path``
    (``file, sequence, frame, reason``); without it, or with ``strict``, any
    such frame is an error naming its file and nothing is written (the
    rejects rule, :func:`hpe_cli.io.rejects.rejects_rule`). With the default
    protocol, labels + rejects = the frames found.
    """
    import numpy as np

    from ..datasets.biwi import protocol_mask, read_biwi_camera, sequence_split
    from ..errors import HpeError
    from ..io import check_output, system_metadata, write_table
    from ..io.rejects import Rejects
    from ..io.writers import AtomicFile
    from ..rotation import get_system

    check_output(output, overwrite)
    rejects = Rejects(rejects_path, overwrite, strict=strict)
    sysobj = get_system(system)
    bad: list = []
    frame = read_biwi_camera(
        input_path, camera=camera, calibration=calibration, head_size_mm=head_size, system=sysobj, bad=bad
    )
    if bad:
        rejects.first_where = bad[0]["message"]  # FILE: reason (each frame is its own file)
        rejects.add(
            {
                c: np.array([b[c] for b in bad], dtype=np.int64 if c == "frame" else object)
                for c in ("file", "sequence", "frame")
            },
            [b["reason"] for b in bad],
        )
    rejects.check()  # before anything is written
    keep = protocol_mask(frame, protocol)
    frame = frame[keep].reset_index(drop=True)
    if frame.empty:
        raise HpeError(f"{input_path}: protocol {protocol} keeps no frame")
    splits = None
    if split is not None:
        splits = sequence_split(frame["sequence"], split, seed)
        where = {s: name for name, seqs in splits.items() for s in seqs}
        frame["split"] = [where[s] for s in frame["sequence"].astype(str)]
    lists = []
    if splits is not None and split_lists is not None:
        d = Path(split_lists)
        for name, seqs in splits.items():  # refuse existing lists before writing anything
            check_output(d / f"{name}_sequences.txt", overwrite)
    meta = {
        **system_metadata(sysobj),
        "hpe:biwi": {
            "camera": camera,
            "head_size_mm": head_size,
            "protocol": protocol,
            "split": None if splits is None else {"fractions": list(split), "seed": seed, "sequences": splits},
        },
    }
    import json

    meta["hpe:biwi"] = json.dumps(meta["hpe:biwi"])
    write_table(frame, output, overwrite, meta)
    rejects.write()
    if splits is not None and split_lists is not None:
        d = Path(split_lists)
        for name, seqs in splits.items():
            p = d / f"{name}_sequences.txt"
            with AtomicFile(p, overwrite) as tmp:
                tmp.write_text("".join(f"{s}\n" for s in seqs), encoding="utf-8")
            lists.append(str(p))
    return {
        "rows": len(frame),
        "dropped": int((~keep).sum()),
        "sequences": int(frame["sequence"].nunique()),
        "splits": {k: len(v) for k, v in (splits or {}).items()},
        "lists": lists,
        "boxes": int(np.isfinite(frame["bbox_w"]).sum()),
        "rejected": len(rejects),
        "rejects_per_reason": dict(rejects.counts),
    }
