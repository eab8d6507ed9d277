"""``hpe biwi``: BIWI labels in the depth or RGB camera, with head boxes, a protocol subset and sequence splits."""
from __future__ import annotations

from pathlib import Path


def run_biwi(input_path, output, *, camera="depth", calibration=None, head_size=200.0, system="biwi",
             protocol="all", split=None, seed=0, split_lists=None, overwrite=False) -> dict:
    """Read BIWI, write the label table (and the split's sequence lists); return a summary dict."""
    import numpy as np

    from ..datasets.biwi import protocol_mask, read_biwi_camera, sequence_split
    from ..errors import HpeError
    from ..io import check_output, system_metadata, write_table
    from ..io.writers import AtomicFile
    from ..rotation import get_system

    check_output(output, overwrite)
    sysobj = get_system(system)
    frame = read_biwi_camera(input_path, camera=camera, calibration=calibration, head_size_mm=head_size,
                             system=sysobj)
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
    meta = {**system_metadata(sysobj), "hpe:biwi": {
        "camera": camera, "head_size_mm": head_size, "protocol": protocol,
        "split": None if splits is None else {"fractions": list(split), "seed": seed, "sequences": splits}}}
    import json

    meta["hpe:biwi"] = json.dumps(meta["hpe:biwi"])
    write_table(frame, output, overwrite, meta)
    if splits is not None and split_lists is not None:
        d = Path(split_lists)
        for name, seqs in splits.items():
            p = d / f"{name}_sequences.txt"
            with AtomicFile(p, overwrite) as tmp:
                tmp.write_text("".join(f"{s}\n" for s in seqs), encoding="utf-8")
            lists.append(str(p))
    return {"rows": int(len(frame)), "dropped": int((~keep).sum()), "sequences": int(frame["sequence"].nunique()),
            "splits": {k: len(v) for k, v in (splits or {}).items()}, "lists": lists,
            "boxes": int(np.isfinite(frame["bbox_w"]).sum())}
