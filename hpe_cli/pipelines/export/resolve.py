"""Export: where a row's pixels are (image file, Panoptic ``hdImgs`` layouts, ``hdVideos``) and a JPEG's size.

Behaviour kept as it was; a shared image resolver (``hpe_cli.io.images``) is meant to replace this module.
"""
from __future__ import annotations

from pathlib import Path

from ...errors import HpeError


def resolve_image(root: str, image: str, sequence: str, camera: str, frame: int):
    """The image file for a row, or None: ``<root>/<image>``, ``<root>/<sequence>/<image>``, and for Panoptic
    rows :func:`hpe_cli.datasets.panoptic.hd_image_path` (``hdImgs/<cam>/<cam>_<frame:08d>.jpg`` or the
    ``hdImgs/hd_<cam>/<frame:08d>.jpg`` layout some copies use) under both."""
    r = Path(root)
    cands = [r / image]
    bases = (r, r / sequence) if sequence else (r,)
    if sequence:
        cands.append(r / sequence / image)
    if camera and frame >= 0:
        from ...datasets.panoptic import hd_image_path

        for base in bases:
            try:
                cands.append(hd_image_path(base, camera, frame))
            except HpeError:
                break
    for c in cands:
        if c.is_file():
            return str(c)
    return None


def video_path(root: str, sequence: str, camera: str):
    """``hdVideos/hd_<cam>.mp4`` under ``root`` or ``root/sequence`` (:func:`~hpe_cli.datasets.panoptic.hd_video_path`)."""
    from ...datasets.panoptic import hd_video_path

    bases = (Path(root), Path(root) / sequence) if sequence else (Path(root),)
    return next((str(v) for v in (hd_video_path(b, camera) for b in bases) if v.is_file()), None)


def jpeg_size(data: bytes):
    """(width, height) from a JPEG's SOF header, or None."""
    if data[:2] != b"\xff\xd8":
        return None
    i, n = 2, len(data)
    while i + 9 < n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            i += 2
            continue
        seg = int.from_bytes(data[i + 2:i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            h = int.from_bytes(data[i + 5:i + 7], "big")
            w = int.from_bytes(data[i + 7:i + 9], "big")
            return (w, h) if w > 0 and h > 0 else None
        i += 2 + seg
    return None
