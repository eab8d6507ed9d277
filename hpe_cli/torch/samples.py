"""Per-sample work of :class:`~hpe_cli.torch.HeadPoseDataset`, kept small: crop boxes, decode, cached pose outputs.

Everything that can be done once for all rows is done in the constructor, vectorised:
the crop rectangles of every row and the pose outputs (stored matrix, angles, gimbal
lock) of every row's canonical matrix, and of its mirror image (the pose after a
horizontal flip) on first use. ``__getitem__`` then decodes the crop's rectangle of the
JPEG straight into RGB (:mod:`hpe_cli.io.jpeg`: OpenCV's pixels; older OpenCV versions
decode BGR and the crop is converted), zeros where the crop leaves the image, optionally
resizes with ``cv2.resize`` and wraps the HWC array as a (3, H, W) tensor without a copy.
"""

from __future__ import annotations

import numpy as np
import torch

from ..geometry.augment import box_of_points
from ..io.jpeg import decode_crop, decode_image, read_crop, read_image
from .collate import Sample
from .transforms import pose_mirror

#: ``interpolation=`` names of :class:`HeadPoseDataset` (``cv2.INTER_*``)
INTERPOLATIONS = ("linear", "area", "cubic", "nearest", "lanczos")


def crop_rects(boxes, points, margin: float, square: bool):
    """Integer crop rectangles ``(top, left, height, width)`` of every row, and which rows have one.

    The box is ``boxes[i]`` where finite, else the box of the finite ``points[i]``; it
    is enlarged by ``margin`` times its width and height on each side, made a square
    around its centre (side: the longer enlarged side, rounded up) when ``square``.

    Parameters
    ----------
    boxes : ndarray (N, 4) or None
        ``x, y, w, h`` pixels.
    points : ndarray (N, L, 2) or None
    margin : float
    square : bool

    Returns
    -------
    rects : ndarray of int64, shape (N, 4)
        ``top, left, height, width`` (rows without a box: zeros).
    ok : ndarray of bool, shape (N,)
    """
    n = len(boxes) if boxes is not None else len(points)
    b = np.full((n, 4), np.nan) if boxes is None else np.array(boxes, dtype=np.float64)
    missing = ~np.isfinite(b).all(axis=1)
    if missing.any() and points is not None:
        b[missing] = box_of_points(points[missing])[0]
    ok = np.isfinite(b).all(axis=1)
    x, y, w, h = (np.where(ok, b[:, k], 0.0) for k in range(4))
    if square:
        size = np.ceil(np.maximum(w, h) * (1.0 + 2.0 * margin))
        left = np.floor(x + w / 2.0 - size / 2.0)
        top = np.floor(y + h / 2.0 - size / 2.0)
        height = width = size
    else:
        left, top = np.floor(x - margin * w), np.floor(y - margin * h)
        width = np.maximum(1.0, np.ceil(x + w + margin * w) - left)
        height = np.maximum(1.0, np.ceil(y + h + margin * h) - top)
    rects = np.stack([top, left, height, width], axis=1).astype(np.int64)
    rects[~ok] = 0
    return rects, ok


def place(boxes, points, origin, scale):
    """Boxes ``(N, 4)`` and points ``(N, L, 2)`` in crops at ``origin`` ``(N, 2)`` resized by ``scale`` ``(N, 2)``.

    ``scale`` None: no resize; else OpenCV's pixel-centre mapping ``x' = (x + 0.5) * s - 0.5``
    (:func:`hpe_cli.geometry.crop.points_to_crop`); widths and heights scale by ``s``.
    Either input may be None (returned as None).
    """
    box = lm = None
    if boxes is not None:
        box = np.array(boxes, dtype=np.float64)
        box[:, :2] -= origin
        if scale is not None:
            box = np.stack(
                [
                    (box[:, 0] + 0.5) * scale[:, 0] - 0.5,
                    (box[:, 1] + 0.5) * scale[:, 1] - 0.5,
                    box[:, 2] * scale[:, 0],
                    box[:, 3] * scale[:, 1],
                ],
                axis=1,
            )
    if points is not None:
        lm = points - origin[:, None]
        if scale is not None:
            lm = (lm + 0.5) * scale[:, None] - 0.5
    return box, lm


def flip_geometry(box, lm, width: int, perm):
    """A box ``(4,)`` and points ``(L, 2)`` after a horizontal flip of a ``width``-pixel image (new arrays).

    ``x -> W - x - w`` (box) and ``x -> W - 1 - x`` with the points re-indexed by ``perm``,
    as torchvision's flips and :class:`hpe_cli.torch.transforms.RandomHorizontalFlip`.
    """
    if box is not None:
        box = box.copy()
        box[0] = width - box[0] - box[2]
    if lm is not None:
        lm = lm[perm]
        lm[:, 0] = (width - 1) - lm[:, 0]
    return box, lm


_FLAGS = {}


def _rgb_flag():
    """``cv2.IMREAD_COLOR_RGB`` (OpenCV >= 4.10: the decoder writes RGB), or None (decode BGR, convert the crop)."""
    if "rgb" not in _FLAGS:
        import cv2

        _FLAGS["rgb"] = getattr(cv2, "IMREAD_COLOR_RGB", None)
    return _FLAGS["rgb"]


def decode(data=None, path=None, rect=None):
    """uint8 pixels of encoded bytes (``data``) or a file (``path``), None if OpenCV cannot decode them.

    The whole frame (H, W, 3), or with ``rect`` ``(top, left, height, width)`` that rectangle of it, zeros
    outside the frame. RGB when OpenCV has ``IMREAD_COLOR_RGB``, else BGR (:func:`as_rgb` converts).
    OpenCV's pixels exactly, with less work where :mod:`hpe_cli.io.jpeg` can: JPEG rectangles decoded over
    the rectangle only, whole JPEGs through libjpeg-turbo's SIMD decoder (``simplejpeg``).
    """
    rgb = _rgb_flag() is not None
    if data is not None and not data.size:
        return None
    if rect is None:
        return decode_image(data, rgb) if data is not None else read_image(path, rgb)
    top, left, h, w = rect.tolist() if isinstance(rect, np.ndarray) else rect
    box = (left, top, left + w, top + h)
    return decode_crop(data, box, rgb) if data is not None else read_crop(path, box, rgb)


def as_rgb(img):
    """A :func:`decode` result in RGB: itself, or (OpenCV older than 4.10, which decodes BGR) converted."""
    if _rgb_flag() is None:
        import cv2

        return cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2RGB)
    return img


def resize(pix, size: int, interpolation: str):
    """``cv2.resize`` to ``size`` x ``size`` with the ``cv2.INTER_*`` named ``interpolation``."""
    import cv2

    flag = _FLAGS.get(interpolation)
    if flag is None:
        flag = _FLAGS[interpolation] = getattr(
            cv2, "INTER_LANCZOS4" if interpolation == "lanczos" else f"INTER_{interpolation.upper()}"
        )
    return cv2.resize(pix, (size, size), interpolation=flag)


def hflip_pixels(pix):
    """The HWC pixels mirrored left-right (``cv2.flip(pix, 1)``: a new contiguous array)."""
    import cv2

    return cv2.flip(np.ascontiguousarray(pix), 1)


def to_tensor(pix) -> torch.Tensor:
    """(3, H, W) uint8 tensor sharing the HWC array's memory (a channels-last view: no copy)."""
    return torch.from_numpy(np.asarray(pix)).permute(2, 0, 1)


#: shared boolean scalars, cloned into each sample's flags
TRUE_TENSOR, FALSE_TENSOR = torch.tensor(True), torch.tensor(False)


class PoseOutputs:
    """The pose outputs of every row in ``system``, computed once (vectorised) and looked up per sample.

    A sample's pose after its transform is looked up when it is the row's own canonical
    matrix (no geometric step, or pose-neutral ones: crops, uniform scaling, colour) or
    its mirror image (a horizontal flip), else converted; :meth:`outputs` converts all
    the misses of a batch in one vectorised call.
    """

    def __init__(self, canonical: np.ndarray, system, dtype):
        self.system, self.dtype = system, dtype
        self.np_dtype = torch.empty(0, dtype=dtype).numpy().dtype
        self.A = torch.from_numpy(np.ascontiguousarray(canonical, dtype=np.float64))
        self._own = self._convert(self.A.numpy())
        self._mirror_A = None
        self._mirror = None

    def __getstate__(self):  # workers rebuild the mirror table if they need it
        state = dict(self.__dict__)
        state["_mirror_A"] = state["_mirror"] = None
        return state

    def _convert(self, A: np.ndarray) -> dict:
        """``(packed, locked)``: matrix, primary angles, canonical (N, 21) in the output dtype; gimbal-lock flags."""
        A = np.asarray(A, dtype=np.float64)
        out = {
            "matrix": np.full(A.shape, np.nan),
            "angles": np.full(A.shape[:-1], np.nan),
            "gimbal_lock": np.zeros(len(A), bool),
        }
        good = np.isfinite(A).all(axis=(1, 2))  # a dropped pose (NaN) stays NaN, unlocked
        if good.any():
            R = self.system.from_canonical(A[good])
            p1, _, locked, _ = self.system.to_angles(R)
            out["matrix"][good], out["angles"][good], out["gimbal_lock"][good] = R, p1, locked
        packed = np.concatenate([out["matrix"].reshape(-1, 9), out["angles"], A.reshape(-1, 9)], axis=1)
        return packed.astype(self.np_dtype), out["gimbal_lock"]

    @staticmethod
    def _row(table, i: int) -> dict:
        """One row of a packed table ``(N, 21)`` (matrix, angles, canonical) as tensors of its own memory."""
        packed, locked = table
        row = torch.from_numpy(packed[i].copy())
        return {
            "matrix": row[:9].view(3, 3),
            "angles": row[9:12],
            "canonical": row[12:].view(3, 3),
            "gimbal_lock": (TRUE_TENSOR if locked[i] else FALSE_TENSOR).clone(),
        }

    def mirrored(self, i: int) -> torch.Tensor:
        """Canonical matrix (1, 3, 3) of row ``i`` after a horizontal flip (from a table built on first use)."""
        if self._mirror_A is None:
            self._mirror_A = pose_mirror(self.A, True)
        return self._mirror_A[i : i + 1]

    def _mirror_table(self):
        if self._mirror is None:
            self.mirrored(0)
            self._mirror = self._convert(self._mirror_A.numpy())
        return self._mirror

    def _lookup(self, i: int, A, flipped: bool):
        if A is None:
            table = self._mirror_table() if flipped else self._own
        elif A.dtype != torch.float64 or A.device.type != "cpu" or A.shape != (3, 3):
            return None
        elif torch.equal(A, self.A[i]):
            table = self._own
        elif torch.equal(A, self.mirrored(i)[0]):
            table = self._mirror_table()
        else:
            return None
        return self._row(table, i)

    def outputs(self, rows) -> list:
        """Pose outputs of ``rows``: ``(i, A, flipped)``, ``A`` the (3, 3) canonical matrix after the transform.

        ``A`` None means the row's own pose (``flipped``: mirrored), untouched since.
        """
        found = [self._lookup(i, A, flipped) for i, A, flipped in rows]
        miss = [k for k, f in enumerate(found) if f is None]
        if miss:
            A = torch.stack([rows[k][1].detach().to("cpu", torch.float64) for k in miss]).numpy()
            conv = self._convert(A)
            for n, k in enumerate(miss):
                found[k] = self._row(conv, n)
        return found


class PackedRows:
    """Every output of a sample but its image, of every row at once: one float table per flip state.

    Row ``i`` of a table holds ``matrix`` (9), ``angles`` (3), ``canonical`` (9), then
    ``box`` (4) and ``landmarks`` (2L) when present, in the output dtype; the flipped
    table has the mirrored pose and the geometry after :func:`flip_geometry` (the same
    float64 operations, vectorised). A sample then costs one row copy and a few views.
    Tables are not pickled (a spawned worker builds its own on first use).

    Parameters
    ----------
    poses : PoseOutputs
    placed : (boxes (N, 4) or None, landmarks (N, L, 2) or None)
        Geometry in the crop's (resized) pixels (:func:`place`).
    ok : ndarray of bool (N,)
        Rows whose geometry is in ``placed`` and whose resize keeps the aspect ratio.
    widths : ndarray (N,)
        Output width of each row (NaN: unknown until decoded, so no flipped row).
    perm : sequence of int or None
        Left/right landmark permutation of a flip.
    flips : sequence of bool
        Tables to build now (the flip states a sample can have), so that ``DataLoader``
        workers forked later share them instead of building their own. Others are built
        on first use. Memory: ``4 * (21 + 4 + 2L)`` bytes per row and table (float32).
    """

    def __init__(self, poses, placed, ok, widths, perm, flips=()):
        self.poses, self.placed, self.ok, self.widths, self.perm = poses, placed, ok, widths, perm
        self._tables = {flip: self._build(flip) for flip in flips}

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_tables"] = {}
        return state

    def _build(self, flip: bool):
        packed, locked = self.poses._mirror_table() if flip else self.poses._own
        box, lm = self.placed
        ok = self.ok & np.isfinite(self.widths) if flip else self.ok
        if flip:
            W = np.where(ok, self.widths, 0.0)
            if box is not None:
                box = box.copy()
                box[:, 0] = W - box[:, 0] - box[:, 2]
            if lm is not None:
                lm = lm[:, self.perm]
                lm[:, :, 0] = (W - 1)[:, None] - lm[:, :, 0]
        parts = [packed] + [a.reshape(len(a), -1).astype(packed.dtype) for a in (box, lm) if a is not None]
        return np.ascontiguousarray(np.concatenate(parts, axis=1)), locked, ok

    def sample(self, i: int, flip: bool, image):
        """The sample dict of row ``i`` (as :class:`HeadPoseDataset` returns it), or None if not tabled."""
        table = self._tables.get(flip)
        if table is None:
            table = self._tables[flip] = self._build(flip)
        values, locked, ok = table
        if not ok[i]:
            return None
        r = values[i].copy()  # the sample's own memory; numpy views of it wrapped (cheaper than torch views)
        wrap, (box, lm) = torch.from_numpy, self.placed
        out = Sample(image=image)
        if box is not None:
            out["box"] = wrap(r[21:25])
        if lm is not None:
            out["landmarks"] = wrap(r[21 if box is None else 25 :].reshape(-1, 2))
        out["matrix"], out["angles"], out["canonical"] = (
            wrap(r[:9].reshape(3, 3)),
            wrap(r[9:12]),
            wrap(r[12:21].reshape(3, 3)),
        )
        out["gimbal_lock"], out["pose_undefined"] = wrap(np.array(locked[i])), wrap(np.array(False))
        out["index"] = i
        return out
