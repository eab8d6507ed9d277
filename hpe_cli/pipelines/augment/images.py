"""``hpe augment``'s pictures: per-row image sizes, the transformed images and, for a ``.mat`` folder, the
``.mat`` files written back beside them.

Images are written into a staged folder (:func:`hpe_cli.io.transaction.staged_dir`) that the run commits as
a whole with the table: a failure, also halfway through the commit, leaves none of them in place.

OpenCV and ``scipy.io`` are imported where a picture or a ``.mat`` file is handled: a table-only run never needs
them, and loading them at import took 0.3 to 1.5 s of its start-up (measured on the 2-core build machine).
"""

from __future__ import annotations

from pathlib import Path, PurePath

import numpy as np

from ...errors import HpeError
from ...geometry.augment import move_point, move_td
from ...geometry.image_ops import cv_flags
from ...io.images import IMAGE_SUFFIXES, ImageResolver, image_size, leaves_root
from ...io.os_errors import os_reason, write_bytes
from .options import AugmentOptions


class RowImages:
    """Resolve each row's picture and its size once per name (thread-safe enough: a dict under the GIL)."""

    def __init__(self, root, optional=False):
        self.resolver = ImageResolver(root)
        self.optional = optional  # a .mat folder's own images: sizes when present, no reject when absent
        self.cache: dict = {}
        self.video_sizes: dict = {}  # a video's frame size, read once (not once per frame)

    def lookup(self, name, sequence="", camera="", frame=-1):
        """``(ref or None, (W, H) or None, reason)``."""
        key = (name, sequence, camera, frame)
        hit = self.cache.get(key)
        if hit is None and leaves_root(name):
            hit = self.cache[key] = (None, None, f"image name {name!r} leaves the --images folder (refused)")
        if hit is None:
            ref = self.resolver.find(name, sequence, camera, frame)
            if ref is None:
                hit = (None, None, "" if self.optional else f"image not found: {self.resolver.tried(name, sequence)}")
            else:
                if ref.video is not None:
                    if ref.video not in self.video_sizes:
                        self.video_sizes[ref.video] = image_size(ref)
                    size = self.video_sizes[ref.video]
                else:
                    size = image_size(ref)
                hit = (ref, size, "" if size is not None else f"not a readable image: {ref}")
            self.cache[key] = hit
        return hit


def output_name(name: str, ref) -> PurePath:
    """The output image's name relative to ``--out-images``: the table's name (an absolute name: its base name),
    with the picture's own suffix when the table names a ``.mat`` or a video frame."""
    p = PurePath(name) if name else PurePath(f"{Path(ref.video).stem}_{ref.frame:08d}.jpg")
    if p.is_absolute():
        p = PurePath(p.name)
    if ".." in p.parts or not p.parts:
        raise HpeError(f"expected an image name inside --images, got {name!r}")
    if p.suffix.lower() not in IMAGE_SUFFIXES:
        suffix = Path(ref.path).suffix if ref.path is not None else ".jpg"
        p = p.with_name((p.stem if p.suffix.lower() == ".mat" else p.name) + suffix)
    return p


class ImageJob:
    """Warp each picture once into the staged folder; write ``.mat`` files back when the input is a ``.mat`` folder.

    ``stage``: the staged ``--out-images`` folder; ``opts``: the run's :class:`~.options.AugmentOptions`
    (``out_images``, ``interpolation``, ``border``, ``jpeg_quality``, ``overwrite``); ``mat_dir``: the input
    ``.mat`` folder (or file) whose ``.mat`` files are written back, read in ``mat_system`` (their Pose_Para's);
    ``perm_of(n)``: the left/right permutation of ``n`` landmarks, or None.
    """

    def __init__(self, stage: Path, opts: AugmentOptions, *, mat_dir=None, mat_system=None, perm_of=None):
        self.stage, self.dst = Path(stage), Path(opts.out_images)
        self.interp, self.border = opts.interpolation, opts.border
        self.quality, self.overwrite = opts.jpeg_quality, opts.overwrite
        self.mat_dir, self.mat_system, self.perm_of = mat_dir, mat_system, perm_of
        self.done: dict = {}  # output name -> (picture key, where of the first row)
        self.mats = 0

    def add_rows(self, rows, tick=None):
        """Transform the pictures of a batch's rows, each picture once.

        ``rows``: ``(name, where, ref, P, size_in, size_out, mirror, mat)`` per row (``mat``: (file, canonical
        A', crop roi fn, zoom) or None). Every output name is checked first; then the pictures are read with
        :meth:`hpe_cli.io.images.ImageResolver.read` (image files in order, each video decoded once, front to
        back) and warped one at a time. ``tick(n)`` is called as ``n`` rows are done.
        """
        todo = []  # (row tuple, rel) of the first row of each new picture
        for row in rows:
            if self._claim(row):
                todo.append(row)
            elif tick is not None:
                tick(1)
        read_flags = None
        if todo:
            import cv2  # lazy: see the module docstring

            read_flags = cv2.IMREAD_UNCHANGED  # keep grey, alpha and 16-bit images as they are
        for k, img, why in ImageResolver.read([r[2] for r in todo], flags=read_flags):
            self._render(todo[k], img, why)
            if tick is not None:
                tick(1)

    def _claim(self, row):
        """Check the row's output name; True when its picture is new (to be warped), False when an earlier row
        already claimed it. A ``.mat`` file is written back either way."""
        name, where, ref, P, size_in, size_out, mirror, mat = row
        try:
            rel = output_name(name, ref)
        except HpeError as exc:
            raise HpeError(f"{where}: {exc}") from None
        key = str(rel)
        if key in self.done:
            if self.done[key][0] != ref.key:
                raise HpeError(
                    f"{where}: image {name!r} ({ref}) would be written to {self.dst / rel}, as the image "
                    f"of {self.done[key][1]} ({self.done[key][0]}) is: two different pictures for one "
                    "output file"
                )
            new = False
        else:
            final = self.dst / rel
            if final.is_dir():
                raise HpeError(f"{final}: is a folder, expected a file name")
            if final.exists() and not self.overwrite:
                raise HpeError(f"{final}: already exists (use --overwrite to replace it)")
            self.done[key] = (ref.key, _row_part(where))
            new = True
        if mat is not None:
            self._write_mat(rel, mat, P, size_in, size_out, mirror, where)
        return new

    def _render(self, row, img, why):
        """Warp one picture into the staged folder."""
        import cv2  # lazy: see the module docstring

        name, where, ref, P, size_in, size_out, _, _ = row
        if img is None:
            raise HpeError(f"{where}: {why or f'{ref}: not a readable image'}")
        h, w = img.shape[:2]
        if (w, h) != tuple(int(x) for x in size_in):
            raise HpeError(f"{where}: {ref} is {w}x{h}, but its header said {size_in[0]:g}x{size_in[1]:g}")
        out = _warp(img, P, size_out, self.interp, self.border)
        rel = output_name(name, ref)
        staged = self.stage / rel
        staged.parent.mkdir(parents=True, exist_ok=True)
        suffix = rel.suffix.lower() or ".png"
        params = [cv2.IMWRITE_JPEG_QUALITY, self.quality] if suffix in (".jpg", ".jpeg") else []
        ok, buf = cv2.imencode(suffix, out, params)
        if not ok:
            raise HpeError(f"{self.dst / rel}: could not encode the image as {suffix}")
        write_bytes(staged, buf, self.dst / rel)  # a full disk names this picture, not the table

    def _write_mat(self, rel, mat, P, size_in, size_out, mirror, where):
        """``<stem>.mat`` beside the output image: Pose_Para (new angles, tdx, tdy), pt2d, pt3d_68 and roi moved;
        every other variable copied."""
        import scipy.io  # lazy: see the module docstring

        src_mat, A2, roi_fn, zoom = mat
        try:
            m = scipy.io.loadmat(src_mat)
        except Exception as exc:  # noqa: BLE001 - scipy raises many types for a damaged file
            raise HpeError(f"{src_mat}: not a readable MATLAB .mat file ({' '.join(str(exc).split())[:120]})") from None
        m = {k: v for k, v in m.items() if not k.startswith("__")}
        s = self.mat_system
        pose = np.asarray(m["Pose_Para"], dtype=np.float64).reshape(-1).copy()
        pose[:3] = np.deg2rad(s.to_angles(s.from_canonical(A2[None]))[0][0])
        tdx, tdy = move_td(pose[3:4], pose[4:5], P, size_in[1], size_out[1], True)
        pose[3], pose[4] = tdx[0], tdy[0]
        pose[6] *= zoom  # weak perspective: projected = scale * R @ X + t; a resize multiplies scale
        m["Pose_Para"] = pose.reshape(1, -1)  # float64: the new angles to the last bit
        if "pt2d" in m:
            m["pt2d"] = self._move_cols(np.asarray(m["pt2d"], dtype=np.float64), P, mirror, invisible=-1.0)
        if "pt3d_68" in m:
            p3 = np.asarray(m["pt3d_68"], dtype=np.float64)
            xy = self._move_cols(p3[:2], P, mirror)
            z = (p3[2][self._perm(p3.shape[1])] if mirror else p3[2]) * zoom
            m["pt3d_68"] = np.vstack([xy, z])
        if "roi" in m and roi_fn is not None:
            m["roi"] = roi_fn(np.asarray(m["roi"], dtype=np.float64), size_in).reshape(m["roi"].shape)
        out = self.stage / rel.with_suffix(".mat")
        out.parent.mkdir(parents=True, exist_ok=True)
        if (self.dst / rel.with_suffix(".mat")).exists() and not self.overwrite:
            raise HpeError(f"{self.dst / rel.with_suffix('.mat')}: already exists (use --overwrite to replace it)")
        try:
            scipy.io.savemat(out, m, do_compression=False)
        except OSError as exc:  # a full disk names this file, not the table
            raise HpeError(f"{self.dst / rel.with_suffix('.mat')}: cannot write: {os_reason(exc)}") from None
        self.mats += 1

    def _perm(self, n):
        perm = self.perm_of(n) if self.perm_of else None
        if perm is None:
            raise HpeError(f"a mirror needs the left/right order of {n} landmarks; no built-in scheme has {n}")
        return perm

    def _move_cols(self, pts, P, mirror, invisible=None):
        """(2, L) points moved by P, re-indexed after a mirror; ``invisible`` marks points (x = -1) kept as is."""
        hidden = (
            (pts[0] == invisible) | (pts[1] == invisible) if invisible is not None else np.zeros(pts.shape[1], bool)
        )
        u, v = move_point(pts[0], pts[1], P)
        out = np.vstack([u, v])
        out[:, hidden] = pts[:, hidden]
        if mirror:
            out = out[:, self._perm(pts.shape[1])]
        return out


def _row_part(where: str) -> str:
    """``line 3`` of ``FILE: line 3``; a ``.mat`` file's own name (it is one row)."""
    return where.split(": ", 1)[-1] if ": " in where else where


def _warp(img, P, size_out, interpolation, border):
    """The picture under the pixel affine ``P`` (2, 3), ``size_out = (W, H)``; flips and integer crops exactly."""
    import cv2  # lazy: see the module docstring

    W, H = (int(x) for x in size_out)
    h, w = img.shape[:2]
    A, t = P[:, :2], P[:, 2]
    if (w, h) == (W, H) and np.array_equal(np.abs(A), np.eye(2)):
        sx, sy = float(A[0, 0]), float(A[1, 1])
        if t[0] == (0.0 if sx > 0 else w - 1.0) and t[1] == (0.0 if sy > 0 else h - 1.0):
            code = {(-1.0, 1.0): 1, (1.0, -1.0): 0, (-1.0, -1.0): -1}.get((sx, sy))
            return img.copy() if code is None else cv2.flip(img, code)
    interp, borders = cv_flags()
    if A[0, 1] == 0 and A[1, 0] == 0 and A[0, 0] == A[1, 1] > 0 and np.allclose(t, 0.5 * A[0, 0] - 0.5):
        # a resize: cv2.resize has the same pixel-centre mapping; area averaging when shrinking
        flag = cv2.INTER_AREA if A[0, 0] < 1 and interpolation == "linear" else interp[interpolation]
        return cv2.resize(img, (W, H), interpolation=flag)
    return cv2.warpAffine(
        img, P, (W, H), flags=interp[interpolation], borderMode=borders[border], borderValue=(0, 0, 0, 0)
    )


__all__ = ["ImageJob", "RowImages", "output_name"]
