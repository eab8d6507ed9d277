"""Which dataset the ground truth of ``hpe evaluate`` is, for protocols whose peer scores datasets differently.

DirectMHP has two scorers (hnuzhy/DirectMHP@a51b06b utils/mae.py): ``mean_absolute_error_calculate_single``
(lines 281-356, AFLW2000, 300W-LP, BIWI: back = ``|GT yaw| > 99``) and ``mean_absolute_error_calculate_v2``
(lines 162-278, CMU Panoptic, AGORA: split at 90). ``--protocol directmhp`` runs the one the peer runs on the GT's
dataset; ``directmhp-single`` / ``directmhp-v2`` name one explicitly.
"""

from __future__ import annotations

import json

#: dataset -> DirectMHP variant
_VARIANT = {
    "AFLW2000-3D / 300W-LP (.mat labels)": "directmhp-single",
    "300W-LP": "directmhp-single",
    "BIWI": "directmhp-single",
    "CMU Panoptic": "directmhp-v2",
    "AGORA": "directmhp-v2",
}


def gt_dataset(src) -> tuple:
    """``(dataset name, how it was recognised)`` of a GT :class:`~hpe_cli.io.readers.TableSource`, or ``(None, "")``.

    Dataset readers (``.mat`` folder, 300W-LP root or zip, BIWI) say so themselves; tables written by
    ``hpe relabel-panoptic`` / ``relabel-agora`` carry ``hpe:relabel`` metadata (Parquet) or their columns
    (``sequence, camera, frame, person_id``; ``source, person, occlusion``).
    """

    path = str(getattr(src, "path", ""))
    if getattr(src, "dataset", False):
        if src.system == "biwi":
            return "BIWI", "BIWI pose files"
        if src.system == "300w_lp":
            low = path.lower()
            if "300w" in low and ("lp" in low or low.endswith(".zip")):
                return "300W-LP", "300W-LP folder"
            return "AFLW2000-3D / 300W-LP (.mat labels)", ".mat label folder"
    meta = (getattr(src.schema, "metadata", None) or {}).get(b"hpe:relabel")
    if meta:
        try:
            source = json.loads(meta).get("source")
        except (ValueError, AttributeError):
            source = None
        if source in ("cmu_panoptic", "agora"):
            return ("CMU Panoptic" if source == "cmu_panoptic" else "AGORA"), "hpe:relabel metadata"
    cols = set(src.columns)
    if {"sequence", "camera", "frame", "person_id"} <= cols:
        return "CMU Panoptic", "columns sequence, camera, frame, person_id (hpe relabel-panoptic)"
    if {"source", "person", "occlusion"} <= cols:
        return "AGORA", "columns source, person, occlusion (hpe relabel-agora)"
    return None, ""


def choose_directmhp(protocols: list, src) -> tuple:
    """``protocols`` with ``directmhp`` replaced by the GT dataset's variant, and a note saying which (or None).

    When the dataset is not known ``directmhp`` stays (the v2 scorer, split at 90) and the note says so.
    """
    if "directmhp" not in protocols:
        return protocols, None
    name, how = gt_dataset(src)
    if name is None:
        return protocols, (
            "directmhp: GT dataset not recognised: DirectMHP's v2 scorer (back = |GT yaw| > 90, "
            "mae.py:162-278); name directmhp-single for AFLW2000, 300W-LP or BIWI labels"
        )
    variant = _VARIANT[name]
    split = (
        "99, mean_absolute_error_calculate_single"
        if variant == "directmhp-single"
        else "90, mean_absolute_error_calculate_v2"
    )
    out = list(dict.fromkeys(variant if p == "directmhp" else p for p in protocols))
    return out, f"directmhp: GT is {name} ({how}): {variant} (back = |GT yaw| > {split})"
