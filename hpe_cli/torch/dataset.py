"""``HeadPoseDataset``: an ``hpe`` label table (or ``.mat`` folder, or exported Parquet) as a PyTorch Dataset."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import torch
from torchvision import tv_tensors
from torchvision.transforms import v2

from ..errors import HpeError
from ..rotation.systems import get_system
from .collate import Sample
from .dataset_tables import (  # noqa: F401
    IMAGE_COLUMNS,
    IMAGE_SUFFIXES,
    canonical_matrices,
    join_paths,
    load_table,
    table_boxes,
    table_landmarks,
)
from .samples import (
    FALSE_TENSOR,
    INTERPOLATIONS,
    TRUE_TENSOR,
    PackedRows,
    PoseOutputs,
    as_rgb,
    crop_rects,
    decode,
    flip_geometry,
    hflip_pixels,
    place,
    resize,
    to_tensor,
)
from .transforms import (
    HeadPose,
    RandomHorizontalFlip,
    aspect_message,
    check_policy,
    is_uniform,
    landmark_flip_permutation,
    no_exact_pose,
)


class HeadPoseDataset(torch.utils.data.Dataset):
    """Images with their head pose, box and landmarks, the pose in the system you ask for.

    Parameters
    ----------
    labels : str, path or pandas.DataFrame
        An ``hpe`` label table (``.parquet``/``.csv`` with ``pitch, yaw, roll`` degrees
        or ``r00..r22``, optional ``bbox_x, bbox_y, bbox_w, bbox_h`` and ``lm{i}_x, lm{i}_y``),
        a folder (or file) of 300W-LP/AFLW2000 ``.mat`` files (``Pose_Para``,
        ``pt2d``, ``pt3d_68``) with the images next to them, a 6DRepNet file list
        (``hpe export --layout 6drepnet``: ``<split>/files.txt`` naming ``.jpg``/``.mat``
        pairs, or ``files_<split>.txt`` with ``<name>.jpg pitch yaw roll`` lines in the
        ``whenet`` system), a Parquet file whose image column holds encoded bytes
        (``{"bytes", "path"}`` structs, as the Hugging Face ``datasets`` Image feature
        stores them), or an ``hpe export --layout hf`` folder (``data/*.parquet`` shards,
        ``landmarks_x/y`` list columns, the system named in its ``README.md`` card).
    images : str or path, optional
        Root of relative image paths (default: the folder of ``labels``).
    system : str, path or RotationSystem
        System of the returned ``matrix`` and ``angles`` (default ``300w_lp``).
    label_system : str, path or RotationSystem, optional
        System of the stored labels. Default: the file's ``hpe:system`` metadata,
        ``300w_lp`` for ``.mat`` input; required for CSV input and DataFrames.
    crop : float, optional
        Crop every sample to its box enlarged by this fraction of the box's width
        and height on each side (``0`` = the box itself; ``None`` = no crop). The box
        is the stored one (``bbox_*``), else the box of the finite landmarks (the
        ``landmarks`` columns, or ``lm`` when ``landmarks=None``). Parts outside the
        image are filled with zeros.
    square : bool
        Make the crop a square around the box centre (side: the longer enlarged side), so
        that a later resize to a square scales uniformly and keeps the pose exact.
        Default True.
    size : int, optional
        Resize the crop to ``size`` x ``size`` with ``cv2.resize`` before the transform
        (the fast path: OpenCV on the HWC array; boxes and landmarks follow with OpenCV's
        pixel-centre mapping ``x' = (x + 0.5) * s - 0.5``). A crop that is not square
        (``square=False``, or a row with no box) is an aspect change: ``on_undefined``.
    interpolation : {"linear", "area", "cubic", "nearest", "lanczos"}
        ``cv2.INTER_*`` of ``size`` (default ``"linear"``, as ``cv2.resize``).
    hflip : float
        Probability of a horizontal flip done in the decode step (``cv2.flip``; the pose
        from a table of the mirrored poses, landmarks re-indexed with ``flip_scheme``),
        as 6DRepNet's and Hopenet's own datasets flip. Same result as
        :class:`hpe_cli.torch.transforms.RandomHorizontalFlip` first in ``transform``,
        without its dispatch cost. Draws ``torch.rand`` (seeded per worker by ``DataLoader``).
    flip_scheme : "auto", {"ibug68", "face70", "aflw21"} or sequence of int
        Left/right landmark permutation of ``hflip`` (``auto``: by the number of landmarks).
    transform : callable, optional
        Called on the sample dict ``{"image": Image, "box": BoundingBoxes (1, 4) XYWH,
        "landmarks": KeyPoints (1, L, 2), "pose": HeadPose (1, 3, 3)}`` (absent keys
        omitted) after the crop; a ``torchvision.transforms.v2`` pipeline moves all of
        them together (use :mod:`hpe_cli.torch.transforms` flips for landmark re-indexing).
        A :class:`hpe_cli.torch.transforms.RandomHorizontalFlip` that is the transform, or
        comes first in a ``v2.Compose``, is done in the decode step as ``hflip`` does (same
        pixels, poses to float rounding, the same ``torch.rand`` draw per sample), about
        twice as fast; the rest of the pipeline runs as given.
    landmarks : str or None
        Column prefix of the 2-D landmarks: ``"lm"`` (``lm{i}_x``; for ``.mat`` input
        ``pt2d``) or ``"lm3d"`` (``.mat`` input: the x, y rows of ``pt3d_68``); None: no
        landmark output (they still give the crop box of rows without a ``bbox``).
    on_undefined : {"raise", "drop", "keep"}
        What a transform step with no exact pose meaning does (shear, perspective,
        elastic, an aspect change such as 6DRepNet's ``RandomResizedCrop(224, scale=(0.8, 1))``):
        raise :class:`~hpe_cli.torch.UndefinedPoseError` (default); ``"drop"`` the pose
        (``matrix``, ``angles``, ``canonical`` NaN) and mark it (``pose_undefined``);
        ``"keep"`` the pose it had before that step, marked.
    dtype : torch.dtype
        Floating dtype of the returned rotations, boxes and landmarks.

    Returns (per item)
    ------------------
    Sample (a ``dict``)
        ``image`` uint8 (3, H, W) RGB (unless ``transform`` converts it; without a
        transform a channels-last view of the decoded pixels), ``matrix`` (3, 3) the
        stored matrix of ``system``, ``angles`` (3,) its primary ``(pitch, yaw, roll)``
        in degrees, ``canonical`` (3, 3), ``gimbal_lock`` bool, ``pose_undefined`` bool
        (see ``on_undefined``), ``box`` (4,) ``(x, y, w, h)`` pixels and ``landmarks``
        (L, 2) pixels (rows going down, NaN = missing) when available, ``index`` int.

    Notes
    -----
    Labels are read and converted once (vectorised, in the constructor), crop boxes
    too; images are decoded lazily in ``__getitem__``, straight into RGB. The pose
    outputs of a sample whose transform left its pose as it was or mirrored it are
    looked up in tables built once; others are converted per batch (``__getitems__``,
    which ``DataLoader`` calls). Without a transform, all outputs but the image are one
    row of a packed table (own or mirrored pose, geometry placed and flipped), copied
    per sample. Samples are :class:`~hpe_cli.torch.collate.Sample` dicts: ``default_collate``
    batches them into one storage (one shared-memory segment per batch from a worker,
    not one per key); the values are the ones ``default_collate`` gives. The object is
    picklable and opens file handles lazily in each ``DataLoader`` worker.

    Examples
    --------
    >>> import numpy as np, pandas as pd, tempfile, cv2, os
    >>> from hpe_cli.torch import HeadPoseDataset
    >>> d = tempfile.mkdtemp(); _ = cv2.imwrite(os.path.join(d, "a.png"), np.zeros((40, 60, 3), np.uint8))
    >>> df = pd.DataFrame({"file": ["a.png"], "pitch": [10.0], "yaw": [20.0], "roll": [0.0],
    ...                    "bbox_x": [10.0], "bbox_y": [5.0], "bbox_w": [20.0], "bbox_h": [20.0]})
    >>> ds = HeadPoseDataset(df, images=d, label_system="300w_lp", system="6drepnet", crop=0.0)
    >>> s = ds[0]
    >>> tuple(s["image"].shape), s["angles"].round(decimals=4), s["box"]
    ((3, 20, 20), tensor([10., 20.,  0.]), tensor([ 0.,  0., 20., 20.]))
    >>> tuple(HeadPoseDataset(df, images=d, label_system="300w_lp", crop=0.5, size=64)[0]["image"].shape)
    (3, 64, 64)
    """

    def __init__(
        self,
        labels,
        images=None,
        system="300w_lp",
        *,
        label_system=None,
        crop=None,
        square=True,
        size=None,
        interpolation="linear",
        hflip=0.0,
        flip_scheme="auto",
        transform=None,
        landmarks="lm",
        on_undefined="raise",
        dtype=torch.float32,
    ):
        self.system = get_system(system)
        self.crop = None if crop is None else float(crop)
        self.square = bool(square)
        if self.crop is not None and not (self.crop >= 0):
            raise ValueError(f"expected crop >= 0 (a margin fraction), got {crop!r}")
        self.size = None if size is None else int(size)
        if self.size is not None and not self.size > 0:
            raise ValueError(f"expected size > 0 (pixels), got {size!r}")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"expected interpolation one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        self.interpolation = interpolation
        self.on_undefined = check_policy(on_undefined)
        self.hflip = float(hflip)
        if not 0.0 <= self.hflip <= 1.0:
            raise ValueError(f"expected hflip a probability in [0, 1], got {hflip!r}")
        self.transform = transform
        self._transform, self._draws = transform, False  # what runs after the crop; v2's flip draw kept
        self.dtype = dtype
        table, found, source, parquet = load_table(labels, landmarks)
        src_system = get_system(label_system) if label_system is not None else found
        if src_system is None:
            raise HpeError(f"{source}: the labels name no rotation system: pass label_system=")
        self.label_system = src_system
        self.source = source
        self.canonical = canonical_matrices(table, src_system, source)
        n = len(table)
        self.images_root = (
            Path(images) if images is not None else (Path(source) if Path(source).is_dir() else Path(source).parent)
        )
        self._parquet = None
        self._image_refs = None
        col = next((c for c in IMAGE_COLUMNS if c in table.columns), None)
        if parquet is not None and col is not None and parquet[1] == col:
            self._parquet = parquet  # (files, column, global row-group offsets, (file, local group) per group)
        elif col is not None:
            self._image_refs = np.asarray(table[col].astype(str))
        else:
            raise HpeError(f"{source}: no image column: expected one of {', '.join(IMAGE_COLUMNS)}")
        self.boxes = table_boxes(table)
        self.landmarks = table_landmarks(table, landmarks)
        self._rects = None
        if self.crop is not None:
            points = self.landmarks if landmarks is not None else table_landmarks(table, "lm")
            if self.boxes is None and points is None:
                raise HpeError(
                    f"{source}: crop= needs bbox_x, bbox_y, bbox_w, bbox_h or landmark columns, found neither"
                )
            self._rects = crop_rects(self.boxes, points, self.crop, self.square)
        peeled = _leading_flip(transform, self.hflip, self.landmarks)
        if peeled is not None:  # hpe's RandomHorizontalFlip first in transform: done in the decode step instead
            self._transform, self.hflip, flip_scheme = peeled
            self._draws = True
        self._perm = None
        if self.hflip > 0 and self.landmarks is not None:
            self._perm = landmark_flip_permutation(flip_scheme, self.landmarks.shape[1])
        self._paths = None if self._image_refs is None else join_paths(self.images_root, self._image_refs)
        self._place_all()
        self._poses = PoseOutputs(self.canonical, self.system, dtype)
        flips = [f for f, can in ((False, self.hflip < 1), (True, self.hflip > 0)) if can and self._transform is None]
        self._rows = PackedRows(self._poses, self._placed, *self._tabled(), self._perm, flips=flips)
        self._n = n
        self._pf = None
        self._rg_cache = (None, None)

    # ---------------------------------------------------------------------------- pickling (workers)
    def __getstate__(self):
        state = dict(self.__dict__)
        state["_pf"] = None
        state["_rg_cache"] = (None, None)
        return state

    def __len__(self):
        return self._n

    def _place_all(self):
        """Boxes and landmarks of every row in its crop's (resized) pixels, where the crop is known here."""
        n = len(self.canonical)
        if self._rects is None:
            origin, known = np.zeros((n, 2)), np.full(n, self.size is None)
        else:
            rects, known = self._rects
            origin = rects[:, [1, 0]].astype(np.float64)
        scale = None
        if self.size is not None:
            with np.errstate(divide="ignore"):
                scale = (
                    np.where(known[:, None], self.size / np.maximum(rects[:, [3, 2]], 1), np.nan)
                    if self._rects is not None
                    else np.full((n, 2), np.nan)
                )
        self._placed = place(self.boxes, self.landmarks, origin, scale)
        self._known = known

    def _tabled(self):
        """Rows whose outputs without a transform are all known here (:class:`PackedRows`), and their widths."""
        n, S = len(self.canonical), self.size
        if self._rects is None:
            return self._known.copy(), np.full(n, np.nan)
        rects, known = self._rects
        hw = np.maximum(rects[:, 2:4], 1).astype(np.float64)
        ok = known.copy()
        if S is not None:  # transforms.is_uniform, vectorised: a crop resized without an aspect change
            lo = np.maximum((S - 0.5) / hw[:, 0], (S - 0.5) / hw[:, 1])
            hi = np.minimum((S + 0.5) / hw[:, 0], (S + 0.5) / hw[:, 1])
            ok &= lo <= hi + 1e-12
        return ok, (np.full(n, float(S)) if S is not None else hw[:, 1])

    # -------------------------------------------------------------------------------------- images
    def _image_path(self, i) -> Path:
        if self._paths[i] is not None:
            return self._paths[i]
        ref = Path(self._image_refs[i])
        path = ref if ref.is_absolute() else self.images_root / ref
        if path.suffix.lower() == ".mat" or not path.suffix:
            for suf in IMAGE_SUFFIXES:
                cand = path.with_suffix(suf)
                if cand.exists():
                    return cand
        return path

    def _image_bytes(self, i):

        files, column, offsets, groups = self._parquet
        if self._pf is None:  # opened lazily, once per worker process
            self._pf = {}
        g = int(np.searchsorted(offsets, i, side="right") - 1)  # global row group
        f, local = groups[g]
        path = files[f]
        if self._rg_cache[0] != g:
            if f not in self._pf:
                self._pf[f] = pq.ParquetFile(path)
            self._rg_cache = (g, self._pf[f].read_row_group(local, columns=[column]).column(0))
        value = self._rg_cache[1][i - int(offsets[g])].as_py()
        if isinstance(value, dict):
            value = value.get("bytes")
        if value is None:
            raise HpeError(f"{path}: row {i + 1}: no image bytes in column {column!r}")
        return np.frombuffer(value, dtype=np.uint8), f"{path}: row {i - int(offsets[g]) + 1} of row group {local}"

    def _decoded(self, i, rect=None):
        """The decoded pixels (H, W, 3) or those of ``rect`` (:func:`~hpe_cli.torch.samples.decode`)."""
        if self._parquet is not None:
            data, where = self._image_bytes(i)
            img = decode(data=data, rect=rect)
        else:
            path = self._image_path(i)
            img, where = decode(path=path, rect=rect), str(path)
            if img is None and not path.exists():
                raise HpeError(f"{path}: no such image (row {i + 1} of {self.source})")
        if img is None:
            raise HpeError(f"{where}: cannot decode image")
        return img

    # -------------------------------------------------------------------------------------- samples
    def _index(self, i) -> int:
        i = int(i)
        if not -self._n <= i < self._n:
            raise IndexError(f"index {i} out of range for {self._n} samples")
        return i % self._n

    def _pixels(self, i, flip):
        """Cropped (resized, flipped) RGB HWC pixels, the crop's ``(left, top)``, its scale ``(sx, sy)``, aspect note."""
        rect = None
        if self._rects is not None and self._rects[1][i]:
            rect = self._rects[0][i].tolist()
        pix = as_rgb(self._decoded(i, rect))  # decoded over the crop only where it can be
        origin = (0, 0) if rect is None else (rect[1], rect[0])
        scale = note = None
        if self.size is not None:
            h, w = pix.shape[:2]  # rows in the packed tables are uniform (checked in _tabled)
            if not self._rows.ok[i] and not is_uniform((h, w), (self.size, self.size)):
                note = aspect_message((h, w), (self.size, self.size), "size= (resize of the crop)")
            pix, scale = resize(pix, self.size, self.interpolation), (self.size / w, self.size / h)
        if flip:
            pix = hflip_pixels(pix)
        return pix, origin, scale, note

    def _geometry(self, i, origin, scale, width, flip):
        """Box (4,) and landmarks (L, 2) of row ``i`` in the crop's (resized, flipped) pixels, float64, or None."""
        box, lm = self._placed
        if self._known[i]:  # placed in the constructor
            box, lm = None if box is None else box[i], None if lm is None else lm[i]
        else:
            sc = None if scale is None else np.array([scale])
            box, lm = place(
                None if box is None else self.boxes[i : i + 1],
                None if lm is None else self.landmarks[i : i + 1],
                np.array([origin], float),
                sc,
            )
            box, lm = None if box is None else box[0], None if lm is None else lm[0]
        if flip:
            box, lm = flip_geometry(box, lm, width, self._perm)
        return box, lm

    def _flip(self) -> bool:
        """Whether this sample is flipped: ``torch.rand`` below ``hflip``. A flip taken over from ``transform``
        draws as ``v2.RandomHorizontalFlip`` does, for every sample (so later random transforms draw the same)."""
        if self._draws:
            return float(torch.rand(())) < self.hflip
        return self.hflip > 0 and (self.hflip >= 1 or float(torch.rand(())) < self.hflip)

    def _prepare(self, i, flip=None, pixels=None):
        """``(partial output, i, A after the transform (None: the table's), undefined flag, flipped)``."""
        if flip is None:
            flip = self._flip()
        pix, origin, scale, note = self._pixels(i, flip) if pixels is None else pixels
        image = to_tensor(pix)
        canvas = tuple(pix.shape[:2])
        box, lm = self._geometry(i, origin, scale, canvas[1], flip)
        pose = None
        if note is not None or self._transform is not None:
            A = self._poses.mirrored(i) if flip else self._poses.A[i : i + 1]
            pose = HeadPose(A, canvas_size=canvas, on_undefined=self.on_undefined)
            if note is not None:
                pose = no_exact_pose(pose, note)
        if self._transform is None:
            out = {"image": image}
            if box is not None:
                out["box"] = torch.from_numpy(box.astype(self._poses.np_dtype))
            if lm is not None:
                out["landmarks"] = torch.from_numpy(lm.astype(self._poses.np_dtype))
            if pose is None:
                return out, i, None, False, flip
            return out, i, pose.as_subclass(torch.Tensor)[0], pose.undefined, flip
        sample = {"image": image.as_subclass(tv_tensors.Image), "pose": pose}
        if box is not None:
            sample["box"] = tv_tensors.BoundingBoxes(torch.from_numpy(box[None]), format="XYWH", canvas_size=canvas)
        if lm is not None:
            sample["landmarks"] = tv_tensors.KeyPoints(torch.from_numpy(lm[None]), canvas_size=canvas)
        sample = self._transform(sample)
        pose = sample["pose"]
        out = {"image": sample["image"]}
        if "box" in sample:
            out["box"] = sample["box"].as_subclass(torch.Tensor)[0].to(self.dtype)
        if "landmarks" in sample:
            out["landmarks"] = sample["landmarks"].as_subclass(torch.Tensor)[0].to(self.dtype)
        return out, i, pose.as_subclass(torch.Tensor)[0], bool(getattr(pose, "undefined", False)), flip

    def _finish(self, prepared) -> list:
        poses = self._poses.outputs([(i, A, flip) for _, i, A, _, flip in prepared])
        result = []
        for (out, i, _, undefined, _), pose in zip(prepared, poses):
            out.update(pose)
            out["pose_undefined"] = (TRUE_TENSOR if undefined else FALSE_TENSOR).clone()
            out["index"] = i
            result.append(Sample(out))
        return result

    def _sample(self, i):
        """The finished sample dict of row ``i`` when its outputs are tabled, else ``_prepare``'s tuple."""
        if self._transform is not None:
            return self._prepare(i)
        flip = self._flip()
        pix, origin, scale, note = self._pixels(i, flip)
        out = None if note is not None else self._rows.sample(i, flip, to_tensor(pix))
        return self._prepare(i, flip, (pix, origin, scale, note)) if out is None else out

    def __getitem__(self, i):
        got = self._sample(self._index(i))
        return got if isinstance(got, dict) else self._finish([got])[0]

    def __getitems__(self, indices) -> list:
        """The samples of a batch (``DataLoader`` calls this): their pose outputs are converted in one call."""
        got = [self._sample(self._index(i)) for i in indices]
        todo = [k for k, g in enumerate(got) if not isinstance(g, dict)]
        for k, out in zip(todo, self._finish([got[k] for k in todo]) if todo else ()):
            got[k] = out
        return got


def _leading_flip(transform, hflip: float, landmarks):
    """``(the rest of transform or None, p, scheme)`` when ``transform`` is, or starts with (``v2.Compose``),
    :class:`hpe_cli.torch.transforms.RandomHorizontalFlip` and ``hflip`` is 0; else None.

    That flip is then done in the decode step, as ``hflip=p`` does (``cv2.flip``, the mirrored-pose table):
    the same pixels, poses to float rounding, the same random draws, without torchvision's dispatch per sample.
    Not when the landmarks fit no permutation of its ``scheme`` (the flip then raises as it would in v2).
    """

    if hflip or transform is None:
        return None
    first, rest = transform, None
    if isinstance(transform, v2.Compose):
        if not transform.transforms:
            return None
        first, more = transform.transforms[0], list(transform.transforms[1:])
        rest = v2.Compose(more) if more else None
    if type(first) is not RandomHorizontalFlip:
        return None
    if landmarks is not None:
        try:
            landmark_flip_permutation(first.scheme, landmarks.shape[1])
        except ValueError:
            return None
    return rest, float(first.p), first.scheme
