"""Export stage 3, place pixels: the worker side (decode each source image or video once, crop every head in
it with padding, resize, encode, write or hand back the pixels)."""

from __future__ import annotations

import os

import numpy as np

from ...errors import HpeError
from ...geometry.crop import crop_padded
from ...io.images import jpeg_size
from ...io.jpeg import crop_band, decode_band
from ...io.os_errors import write_bytes
from ..heap import raise_malloc_thresholds
from .options import NO_FILES, NO_VIDEO

_CFG: dict = {}
_LAST_FRAME: list = [None]


def init_worker(cfg):
    """Pool initializer: keep the job's config in the worker process."""
    global _CFG
    _CFG = cfg
    import cv2

    cv2.setNumThreads(1)
    _frame_sized_malloc()


def _frame_sized_malloc() -> None:
    """Undo, in this process, what ``MALLOC_TRIM_THRESHOLD_`` does to decoding frames.

    Dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536``
    (dask/distributed@2026.8.0 ``distributed/distributed.yaml:195-197``, ``nanny.pre-spawn-environ``). Setting
    it also fixes glibc's mmap threshold (``mallopt(3)``: an explicit threshold turns off the dynamic one), so
    every multi-MB frame is mapped and unmapped and each decode faults in fresh pages: measured here, 1.7x the
    CPU per export unit. Large thresholds (frames are at most 8K x 4K x 3 bytes) restore the default behaviour
    (:func:`hpe_cli.pipelines.heap.raise_malloc_thresholds`).
    """
    if "MALLOC_TRIM_THRESHOLD_" in os.environ:
        raise_malloc_thresholds(128 << 20, 256 << 20)


def _encode(crop, cfg):
    import cv2

    ok, buf = cv2.imencode(".jpg", crop, [cv2.IMWRITE_JPEG_QUALITY, cfg["quality"]])
    if not ok:
        raise HpeError("cannot encode a JPEG crop")
    return buf


class _Band:
    """The part of a frame that a task's heads need, decoded alone (:func:`hpe_cli.io.jpeg.decode_band`):
    stands in for the decoded frame (``shape`` is the frame's)."""

    def __init__(self, band):
        self.band = band
        self.shape = band[2] + (3,)


def _band(data, items):
    """The union of the items' crop boxes of a JPEG, decoded over that union only, or None (decode it all)."""
    boxes = np.array([it[3] for it in items], dtype=np.int64).reshape(-1, 4)
    if not len(boxes):
        return None
    union = (*boxes[:, :2].min(axis=0).tolist(), *boxes[:, 2:].max(axis=0).tolist())
    band = decode_band(data, union, rgb=False)  # BGR, as cv2.imdecode(IMREAD_COLOR)
    return None if band is None else _Band(band)


def _process_image(image, data, items, cfg, out):
    """Crop/encode every item of one decoded image, or of the part of it they need (a :class:`_Band`), or copy
    the file for full frames."""
    import cv2

    H, W = image.shape[:2]
    wrote_full = False
    for it in items:
        idx, split, rel, box, bbox, osz, want = it
        if want is not None and want != (W, H):  # e.g. a 1280x720 video for a 1920x1080 calibration
            reason = (
                f"image size {W}x{H} differs from the labels' image_width x image_height "
                f"{want[0]}x{want[1]} (boxes would be cut from the wrong pixels)"
            )
            out.append((idx, reason, W, H, None))
            continue
        bx, by, bw, bh = bbox  # fraction of the head box inside the frame (scalar form of inside_fraction)
        iw = max(0.0, min(bx + bw, W) - max(bx, 0.0))
        ih = max(0.0, min(by + bh, H) - max(by, 0.0))
        frac = iw * ih / (bw * bh) if bw * bh > 0 else 0.0
        if frac < cfg["min_inside"]:
            out.append((idx, f"box outside the image ({frac * 100:.0f}% inside)", W, H, None))
            continue
        if cfg["full_frames"]:
            if not wrote_full:
                dst = os.path.join(cfg["root"], cfg["split_dirs"][split], rel)
                os.makedirs(os.path.dirname(dst), exist_ok=True)
                write_bytes(dst, data if data is not None else _encode(image, cfg), _shown(cfg, split, rel))
                wrote_full = True
            out.append((idx, "", W, H, None))
            continue
        if isinstance(image, _Band):
            crop = crop_band(image.band, box, cfg["pad_value"])
        else:
            crop = crop_padded(image, box, cfg["pad_value"])
        if osz is not None and (crop.shape[1], crop.shape[0]) != tuple(osz):
            crop = cv2.resize(
                crop, tuple(osz), interpolation=cv2.INTER_AREA if osz[0] < crop.shape[1] else cv2.INTER_LINEAR
            )
        if cfg["pixels"] == "array":
            out.append((idx, "", W, H, _spill(np.ascontiguousarray(crop), cfg)))
            continue
        buf = _encode(crop, cfg)
        if cfg["pixels"] == "jpeg":
            out.append((idx, "", W, H, _spill(buf.tobytes(), cfg)))
        else:
            dst = os.path.join(cfg["root"], cfg["split_dirs"][split], rel)
            d = os.path.dirname(dst)
            if d not in cfg["made"]:
                os.makedirs(d, exist_ok=True)
                cfg["made"].add(d)
            write_bytes(dst, buf, _shown(cfg, split, rel))
            out.append((idx, "", W, H, None))


def _shown(cfg, split, rel) -> str:
    """The path of a picture as the user will see it (not the staged or parts name)."""
    return os.path.join(cfg.get("shown", cfg["root"]), cfg["split_dirs"][split], rel)


def _spill(payload, cfg):
    """Pixels go to the unit's spill file (a unit can hold thousands of heads): the parent reads them back
    one by one, so neither process holds a whole unit's crops."""
    fh = cfg.get("spill")
    if fh is None:
        return payload
    if isinstance(payload, np.ndarray):
        data, shape = payload.tobytes(), payload.shape
    else:
        data, shape = payload, None
    off = fh.tell()
    fh.write(data)
    return ("spill", off, len(data), shape)


def unspill(payload, fh):
    """A worker's payload, read back from the spill file ``fh`` when it was spilled there."""
    if isinstance(payload, tuple) and payload and payload[0] == "spill":
        _, off, n, shape = payload
        fh.seek(off)
        data = fh.read(n)
        return np.frombuffer(data, np.uint8).reshape(shape) if shape is not None else data
    return payload


def work_items(task, cwd=None):
    """One task: an image file (or a video with its frames) and the heads to crop from it. A relative source
    path is read relative to ``cwd`` (the folder the run was started in: a Dask worker runs elsewhere);
    messages name it as the user gave it."""
    import cv2

    cfg = _CFG
    kind, src, groups = task[:3]
    path = os.path.join(cwd, src) if cwd and isinstance(src, str) and kind != "refused" else src
    seek = len(task) > 3 and bool(task[3])  # a block of a long video (units.make_units): one seek to its start
    out = []
    if kind == "video":
        try:
            from ...datasets.panoptic_video import VideoFrames
        except ImportError:
            return [(it[0], NO_VIDEO, -1, -1, None) for items in groups.values() for it in items]
        if src is None:
            return [(it[0], NO_FILES, -1, -1, None) for items in groups.values() for it in items]
        try:
            for fr, img, reason in (
                VideoFrames(path).read(sorted(groups), seek=True) if seek else VideoFrames(path).read(sorted(groups))
            ):
                items = groups.get(fr, [])
                if img is None:
                    out += [(it[0], f"no image (video {src} frame {fr}: {reason})", -1, -1, None) for it in items]
                else:
                    n0 = len(out)
                    _process_image(img, None, items, cfg, out)
                    # a reason about the pixels names the video read and its frame (no hdImgs file was read)
                    out[n0:] = [(o[0], o[1] and f"{o[1]} (video {src} frame {fr})", *o[2:]) for o in out[n0:]]
        except Exception as exc:  # a broken video: every head it should give is a reject
            done = {o[0] for o in out}
            out += [
                (it[0], f"no image (video {src}: {' '.join(str(exc).split())[:120]})", -1, -1, None)
                for items in groups.values()
                for it in items
                if it[0] not in done
            ]
        return out
    items = groups
    if kind == "refused":  # src is the reason
        return [(it[0], src, -1, -1, None) for it in items]
    if src is None:
        return [(it[0], "no image (file not found)", -1, -1, None) for it in items]
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        return [(it[0], f"no image ({exc.strerror or exc})", -1, -1, None) for it in items]
    if truncated_jpeg(data):
        return [
            (it[0], "unreadable image (truncated JPEG: no end-of-image marker after its last scan)", -1, -1, None)
            for it in items
        ]
    if cfg["full_frames"] and src.lower().endswith((".jpg", ".jpeg")):
        size = jpeg_size(data)
        if size is not None:  # copy the JPEG as is: no decode needed for the whole frame
            _process_image(_SizeOnly(size), data, items, cfg, out)
            return out
    if not data:
        return [(it[0], "unreadable image (empty file)", -1, -1, None) for it in items]
    if not cfg["full_frames"]:  # crops only: decode the part of a JPEG that the heads need (OpenCV's pixels)
        band = _band(data, items)
        if band is not None:
            _process_image(band, None, items, cfg, out)
            return out
    try:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:  # OpenCV asserts on some inputs instead of returning None
        image = None
    # keep this frame alive until the next one is decoded: freeing a multi-MB frame before the next allocation
    # makes every decode fault in fresh pages (measured: decoding 1080p JPEGs about 25% slower)
    _LAST_FRAME[0] = image
    if image is None:
        return [(it[0], "unreadable image", -1, -1, None) for it in items]
    _process_image(
        image, data if cfg["full_frames"] and src.lower().endswith((".jpg", ".jpeg")) else None, items, cfg, out
    )
    return out


def truncated_jpeg(data: bytes) -> bool:
    """A JPEG (``FF D8`` first) with no scan (``FF DA``), or whose last scan has no end-of-image marker (``FF D9``)
    after it.

    Entropy-coded data escapes ``FF`` as ``FF 00``, so neither marker appears inside a scan; an EXIF thumbnail's
    own ``FF D9`` comes before the main image's scans. OpenCV decodes such a file without an error, filling the
    missing rows with grey.
    """
    if data[:2] != b"\xff\xd8":
        return False
    sos = data.rfind(b"\xff\xda")
    return sos < 0 or data.rfind(b"\xff\xd9") < sos


class _SizeOnly:
    """Stands in for a decoded image when only its size is needed (full frames copied as files)."""

    def __init__(self, size):
        self.shape = (size[1], size[0], 3)
