"""``hpe view``'s pictures: one thumbnail per row and one reduced full frame per image, made in parallel (threads), cached.

Every picture is named by a content key (BLAKE2b of the source file's identity -- path, size, modification
time -- and of everything drawn on it: crop, centre, length, both poses, size, :data:`VERSION`), so a second run
into the same page folder makes only the pictures of new or changed rows (the files of the first run are kept
where they are; see :func:`plan_pictures`).

The work is cut into tasks: at most :data:`TASK_ROWS` rows of one image file, decoded once with the loader's
decoder (:func:`hpe_cli.io.jpeg.read_image`: simplejpeg where it gives OpenCV's pixels); or every frame of one
video that needs a picture, the video decoded once, front to back (:meth:`hpe_cli.io.images.ImageResolver.read`,
:class:`hpe_cli.datasets.panoptic_video.VideoFrames`: a task per frame would decode the video from its start
for each). A task writes its JPEGs straight into the run's staged folder, so the parent holds only the plan
and memory stays flat (one frame at a time).
"""

from __future__ import annotations

import hashlib
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ...geometry import draw as g
from ...geometry.crop import crop_padded
from ...io.images import ImageResolver
from ...io.jpeg import read_image
from ..pools import in_order

#: thumbnail side, pixels (square)
THUMB = 128
#: longest side of a full frame shown in the detail view, pixels
FRAME_SIDE = 960
#: bump when the drawing changes: every cached picture is made again
VERSION = 1
#: rows per worker task (one image each)
TASK_ROWS = 512
#: the crop is the head box's longer side times this, square, around the box centre
CROP_SCALE = 1.6
THUMB_DIR = "thumbs"
FRAME_DIR = "frames"


@dataclass
class Task:
    """Pictures to make from one image file, or from frames of one video (decoded once, front to back).

    ``items``: ``[(ref, frame name or None, rows)]``, one per picture; ``ref`` a
    :class:`hpe_cli.io.images.ImageRef`; the frame name is the reduced full frame to write; ``rows`` the
    thumbnails, each ``(name, crop (x0, y0, x1, y1) or None, centre, length, V, A_other)``.
    """

    items: list = field(default_factory=list)
    stage: str = ""

    @property
    def n(self) -> int:
        """Thumbnails this task makes."""
        return sum(len(rows) for _, _, rows in self.items)


def _fingerprint(ref) -> str:
    """Path, size and modification time of the picture's file (or video)."""
    path = ref.path if ref.path is not None else ref.video
    try:
        st = os.stat(path)
        return f"{ref.key}|{st.st_size}|{st.st_mtime_ns}"
    except OSError:
        return f"{ref.key}|?"


def picture_keys(fingerprints, crops, centre, length, A, A_other) -> np.ndarray:
    """One 20-hex-digit name per row from its image's fingerprint and what is drawn on it.

    ``fingerprints`` (N,) str; ``crops`` (N, 4) int (-1 for whole frame); ``centre`` (N, 2); ``length`` (N,);
    ``A``, ``A_other`` (N, 3, 3) canonical matrices (``A_other`` NaN where there is none).
    """
    n = len(fingerprints)
    nums = np.concatenate(
        [
            crops.astype(np.float64),
            np.round(centre, 2),
            np.round(length, 2)[:, None],
            np.round(A.reshape(n, 9), 5),
            np.round(A_other.reshape(n, 9), 5),
        ],
        axis=1,
    )
    nums = np.where(np.isfinite(nums), nums, 0.0) + 0.0  # -0.0 and NaN hash alike
    rows = np.ascontiguousarray(nums).view(np.uint8).reshape(n, -1)
    salt = f"v{VERSION}|{THUMB}|{CROP_SCALE}|".encode()
    out = np.empty(n, dtype=object)
    for i in range(n):  # one hash call per row: ~1 us
        h = hashlib.blake2b(salt + fingerprints[i].encode(), digest_size=10)
        h.update(rows[i].tobytes())
        out[i] = h.hexdigest()
    return out


def crop_boxes(frame_boxes) -> np.ndarray:
    """Square integer crops ``(x0, y0, x1, y1)`` around the head boxes ``(N, 4)`` (x, y, w, h); -1 rows where
    the box is missing or empty (those rows get a whole-frame thumbnail)."""
    b = np.asarray(frame_boxes, dtype=np.float64).reshape(-1, 4)
    ok = np.isfinite(b).all(axis=1) & (b[:, 2] > 0) & (b[:, 3] > 0)
    side = np.maximum(b[:, 2], b[:, 3]) * CROP_SCALE
    cx, cy = b[:, 0] + b[:, 2] / 2, b[:, 1] + b[:, 3] / 2
    out = np.full((len(b), 4), -1, dtype=np.int64)
    with np.errstate(invalid="ignore"):
        x0 = np.floor(cx - side / 2)
        y0 = np.floor(cy - side / 2)
        s = np.ceil(side)
    ok &= np.isfinite(x0) & np.isfinite(y0) & (np.abs(x0) < 2**30) & (np.abs(y0) < 2**30) & (s < 2**30)
    out[ok] = np.stack([x0, y0, x0 + s, y0 + s], axis=1)[ok].astype(np.int64)
    return out


def _draw(img, V, A_other, centre, length):
    """The labels' three lines solid (Hopenet's ``draw_axis`` colours and order, anti-aliased, sub-pixel ends:
    :func:`hpe_cli.geometry.draw.render_axes` with the vectors computed for every row at once), OTHER's dashed
    (:func:`hpe_cli.geometry.draw.render_axes_dashed`)."""
    c = np.asarray(centre, dtype=np.float64)
    if not (np.isfinite(c).all() and np.isfinite(length) and length > 0):
        return img
    if V is not None and np.isfinite(V).all():
        one = 1 << _SHIFT
        p = (int(round(c[0] * one)), int(round(c[1] * one)))
        ends = np.clip(c + length * np.asarray(V), -1e6, 1e6)
        for i in range(3):
            q = (int(round(ends[i, 0] * one)), int(round(ends[i, 1] * one)))
            cv2.line(img, p, q, g.AXIS_COLOURS[i], 2, cv2.LINE_AA, _SHIFT)
    if A_other is not None and np.isfinite(A_other).all():
        g.render_axes_dashed(img, np.asarray(A_other).reshape(1, 3, 3), c.reshape(1, 2), length, 1)
    return img


#: sub-pixel bits of the line end points (as :mod:`hpe_cli.geometry.draw`)
_SHIFT = 4


def _shrink(part, size: int):
    """``part`` (square) resized to ``size``: by an integer factor with area averaging first when it is more than
    twice as large (OpenCV's fast path), then bilinear. Returns ``(image, scale)``."""
    side = part.shape[0]
    k = side // size
    if k >= 2:
        m = side // k
        part = cv2.resize(part[: m * k, : m * k], (m, m), interpolation=cv2.INTER_AREA)
        scale0 = 1.0 / k
    else:
        scale0 = 1.0
    out = cv2.resize(part, (size, size), interpolation=cv2.INTER_LINEAR)
    return out, scale0 * size / part.shape[0]


def _interpolation(scale: float) -> int:
    """Area averaging when shrinking by more than 2 (no aliasing), bilinear otherwise (OpenCV's area
    resampling at a non-integer factor costs about 5x bilinear)."""
    return cv2.INTER_AREA if scale < 0.5 else cv2.INTER_LINEAR


def thumbnail(img, crop, V, A_other, centre, length, size: int = THUMB) -> np.ndarray:
    """A ``size`` x ``size`` BGR thumbnail of ``img``: the square ``crop`` (padded with grey outside the image)
    or, with ``crop`` None, the whole frame letterboxed; the labels' pose drawn solid (``V``: the (3, 2) image
    directions of its three lines, :func:`hpe_cli.geometry.draw.image_vectors`) and ``A_other`` dashed at
    ``centre`` (image pixels) with lines ``length`` pixels long."""
    centre = np.asarray(centre, dtype=np.float64)
    if crop is not None:
        x0, y0, x1, y1 = (int(v) for v in crop)
        out, s = _shrink(crop_padded(img, (x0, y0, x1, y1), value=48), size)
        c = (centre - (x0, y0)) * s
    else:
        H, W = img.shape[:2]
        s = size / max(H, W)
        w, h = max(1, round(W * s)), max(1, round(H * s))
        small = cv2.resize(img, (w, h), interpolation=_interpolation(s))
        out = np.full((size, size, 3), 48, dtype=np.uint8)
        ox, oy = (size - w) // 2, (size - h) // 2
        out[oy : oy + h, ox : ox + w] = small
        c = centre * s + (ox, oy)
    return _draw(np.ascontiguousarray(out), V, A_other, c, length * s)


def reduced_frame(img, side: int = FRAME_SIDE) -> np.ndarray:
    """``img`` with its longer side at most ``side`` pixels."""
    H, W = img.shape[:2]
    s = min(1.0, side / max(H, W))
    if s >= 1.0:
        return img
    return cv2.resize(img, (max(1, round(W * s)), max(1, round(H * s))), interpolation=cv2.INTER_AREA)


def _write_jpeg(path: str, img, quality: int) -> None:
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise OSError(f"cannot encode {os.path.basename(path)}")
    with open(path, "wb") as fh:
        fh.write(buf)


def run_task(task: Task) -> tuple:
    """Make the pictures of one task; ``(thumbnails made, [(ref, reason, thumbnails not made)] of the pictures
    that could not be read)``. Videos: :meth:`hpe_cli.io.images.ImageResolver.read` yields each frame once, in frame order."""
    refs = [ref for ref, _, _ in task.items]
    if len(refs) == 1 and refs[0].path is not None:  # the loader's decoder: simplejpeg where it gives OpenCV's pixels
        img = read_image(refs[0].path, rgb=False)
        pictures = [(0, img, "" if img is not None else "not a readable image")]
    else:
        pictures = ImageResolver.read(refs)
    made, failed = 0, []
    for i, img, why in pictures:
        ref, frame_name, rows = task.items[i]
        if img is None:
            failed.append((ref, why or "not a readable image", len(rows)))
            continue
        made += _pictures(img, frame_name, rows, task.stage)
    return made, failed


def _pictures(img, frame_name, rows, stage) -> int:
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if frame_name is not None:
        _write_jpeg(os.path.join(stage, FRAME_DIR, frame_name), reduced_frame(img), 85)
    thumbs = os.path.join(stage, THUMB_DIR)
    for name, crop, centre, length, V, A_other in rows:
        _write_jpeg(os.path.join(thumbs, name), thumbnail(img, crop, V, A_other, centre, length), 82)
    return len(rows)


def existing(outdir: Path, sub: str) -> set:
    """Names of the pictures an earlier run left in ``outdir/sub`` (the cache)."""
    try:
        return {e.name for e in os.scandir(outdir / sub) if e.is_file()}
    except OSError:
        return set()


def make_tasks(groups, stage, thumbs_needed, frames_needed) -> list:
    """Cut ``groups`` (``[(ref, frame name, [row tuples])]``) into :class:`Task` s, keeping only the rows whose
    thumbnail is needed and the frames that are needed: an image file's rows by at most :data:`TASK_ROWS`;
    the frames of one video all in one task, in frame order (the video is decoded once)."""
    tasks, videos = [], {}
    for ref, frame_name, rows in groups:
        rows = [r for r in rows if r[0] in thumbs_needed]
        want_frame = frame_name if frame_name in frames_needed else None
        if not rows and want_frame is None:
            continue
        if ref.path is None:
            videos.setdefault(ref.video, []).append((ref, want_frame, rows))
            continue
        for k in range(0, max(1, len(rows)), TASK_ROWS):
            tasks.append(Task([(ref, want_frame if k == 0 else None, rows[k : k + TASK_ROWS])], str(stage)))
    for items in videos.values():
        tasks.append(Task(sorted(items, key=lambda it: it[0].frame), str(stage)))
    return tasks


def run_tasks(tasks, threads: int, progress=None) -> list:
    """Run the tasks (on ``threads`` threads when more than one: OpenCV's decode, resize, drawing and encode
    release the GIL); ``[(ref, reason, thumbnails not made)]`` of the pictures that could not be read."""
    failed = []

    def done(task, res):
        failed.extend(res[1])
        if progress is not None:
            progress.update(task.n)

    if threads <= 1 or len(tasks) <= 1:
        for t in tasks:
            done(t, run_task(t))
        return failed
    with ThreadPoolExecutor(threads, thread_name_prefix="hpe-view") as pool:
        for t, res in zip(tasks, in_order(pool, run_task, tasks, ahead=4 * threads)):
            done(t, res)
    return failed


def mkdirs(stage: Path) -> None:
    """The picture folders (:data:`THUMB_DIR`, :data:`FRAME_DIR`) in the staged page folder."""
    (stage / THUMB_DIR).mkdir(parents=True, exist_ok=True)
    (stage / FRAME_DIR).mkdir(parents=True, exist_ok=True)


def fingerprint_all(refs) -> list:
    """:func:`_fingerprint` of each distinct picture."""
    return [_fingerprint(r) for r in refs]
