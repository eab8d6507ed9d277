"""One image resolver for every command that reads the pictures behind a label table (draw, augment, export).

A table row names its image in one of these ways, all resolved here:

- a name relative to the image root (``--images``, default: the table's folder), also tried under
  ``<root>/<sequence>/`` when the row has a ``sequence``;
- an absolute name, used as is (and, when it does not exist, its base name under the root);
- a ``.mat`` label name (300W-LP / AFLW2000-3D): the image with the same stem beside it
  (``image00050.mat`` -> ``image00050.jpg``), any of :data:`IMAGE_SUFFIXES`; a name without a
  suffix is tried with each of them too;
- a CMU Panoptic view (``camera`` and ``frame`` columns, or a name such as
  ``hdImgs/00_08/00_08_00001147.jpg``): panoptic-toolbox's extracted frames
  (``hdImgs/00_XX/00_XX_%08d.jpg``, ``scripts/hdImgsExtractor.sh``; ``vgaImgs/XX_XX/XX_XX_%08d.jpg``,
  ``vgaImgsExtractor.sh``; ``kinectImgs/50_XX/50_XX_%08d.jpg``), the ``hdImgs/hd_00_XX/%08d.jpg`` layout some
  mirrors use, and, when no frame file exists, frame ``k`` of the video ``hdVideos/hd_00_XX.mp4``
  (``vgaVideos/vga_XX_XX.mp4``, ``kinectVideos/kinect_50_XX.mp4``) read with
  :class:`hpe_cli.datasets.panoptic_video.VideoFrames`.

Each folder layout is an entry of :data:`IMAGE_LAYOUTS` (``names``, ``panoptic``) giving a row's candidate
files; a new layout is one registered function.

:func:`resolve_image`, :func:`video_path` and :func:`jpeg_size` keep the signatures of
``hpe_cli.pipelines.export`` (a superset of what they find), so export can call them from here.
"""

from __future__ import annotations

import posixpath
import re
from dataclasses import dataclass
from pathlib import Path, PurePath

import numpy as np

from ..registry import Registry

#: suffixes of image files tried for a ``.mat`` name or a name without suffix
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
#: columns tried, in order, for the image name of a row
IMAGE_COLUMNS = ("image", "image_path", "img_path", "file_name", "filename", "file", "path")

#: Panoptic camera types: (image folder, video folder, video prefix)
_PANOPTIC = {
    "hd": ("hdImgs", "hdVideos", "hd_"),
    "vga": ("vgaImgs", "vgaVideos", "vga_"),
    "kinect": ("kinectImgs", "kinectVideos", "kinect_"),
}
_CAM = r"(?P<cam>\d\d_\d\d)"
#: extracted-frame names of the toolbox (``hdImgs/00_08/00_08_00001147.jpg``) and of the mirrors
#: (``hdImgs/hd_00_08/00001147.jpg``)
_PANOPTIC_NAME = re.compile(
    r"(?:^|/)(?P<dir>hdImgs|vgaImgs|kinectImgs)/(?:(?:hd_|vga_|kinect_)?"
    + _CAM
    + r")/(?:(?P=cam)_)?(?P<frame>\d{1,9})\.(?:jpe?g|png)$",
    re.IGNORECASE,
)
_CAM_RE = re.compile(r"^\d\d_\d\d$")


def camera_type(camera: str, image_dir: str = "") -> str:
    """``hd``, ``vga`` or ``kinect`` for a Panoptic camera name (``00_XX`` HD, ``50_XX`` Kinect, else VGA)."""
    d = image_dir.lower()
    if d.startswith("vga"):
        return "vga"
    if d.startswith("kinect"):
        return "kinect"
    if d.startswith("hd"):
        return "hd"
    panel = str(camera)[:2]
    return "hd" if panel == "00" else "kinect" if panel == "50" else "vga"


def panoptic_view(name: str):
    """``(camera type, camera, frame)`` from a Panoptic frame name, or None."""
    m = _PANOPTIC_NAME.search(str(name).replace("\\", "/"))
    if m is None:
        return None
    return camera_type(m["cam"], m["dir"]), m["cam"], int(m["frame"])


def _panoptic_frames(base: Path, kind: str, camera: str, frame: int):
    img_dir, _, prefix = _PANOPTIC[kind]
    root = base / img_dir
    return (
        root / camera / f"{camera}_{frame:08d}.jpg",
        root / f"{prefix}{camera}" / f"{frame:08d}.jpg",
        root / camera / f"{frame:08d}.jpg",
    )


def _bases(root, sequence) -> tuple:
    r = Path(root)
    return (r, r / str(sequence)) if sequence else (r,)


def leaves_root(image) -> bool:
    """True when a relative image name climbs out of its root folder (``../x.jpg``, ``a/../../x.jpg``).

    Such names are refused rather than read: a label table must not make hpe read (and copy into an
    export or a drawing) files outside the folder given with ``--images``. Absolute names are the user's
    own choice and are not affected.
    """

    name = str(image).replace("\\", "/")
    if not name or PurePath(name).is_absolute():
        return False
    return posixpath.normpath(name).split("/")[0] == ".."


def _name_candidates(root: Path, image: str, sequence: str) -> list:
    p = PurePath(image)
    out = []
    if p.is_absolute():
        out.append(Path(p))
        out.append(root / p.name)
    else:
        out += [b / p for b in _bases(root, sequence)]
    more = []
    for c in out:
        if c.suffix.lower() not in IMAGE_SUFFIXES:  # a .mat label, or no suffix: the image beside it
            stem = c.with_suffix("") if c.suffix.lower() == ".mat" else c
            for s in IMAGE_SUFFIXES:
                more += [stem.with_name(stem.name + s), stem.with_name(stem.name + s.upper())]
    return [c for c in out if c.suffix.lower() != ".mat"] + more


#: name -> ``candidates(root: Path, image: str, sequence, camera, frame) -> list of Path``: the files an image
#: folder layout puts a row's image at; :func:`resolve_image` tries every layout's candidates, in order
IMAGE_LAYOUTS = Registry("image layout")


@IMAGE_LAYOUTS.register("names")
def named_candidates(root: Path, image: str, sequence="", camera="", frame=-1) -> list:
    """The row's image name under the root (and ``<root>/<sequence>/``), absolute names, ``.mat`` stems."""
    return _name_candidates(root, str(image), sequence) if image else []


@IMAGE_LAYOUTS.register("panoptic")
def panoptic_candidates(root: Path, image: str, sequence="", camera="", frame=-1) -> list:
    """A CMU Panoptic view's extracted frame files (toolbox and mirror layouts), under the root and sequence."""
    view = _view_of(image, camera, frame)
    if view is None:
        return []
    kind, cam, fr = view
    return [c for base in _bases(root, sequence) for c in _panoptic_frames(base, kind, cam, fr)]


def resolve_image(root, image, sequence="", camera="", frame=-1):
    """The image file for a row, or None.

    Parameters
    ----------
    root : str or Path
        The image root (``--images``).
    image : str
        The row's image name (may be empty when ``camera`` and ``frame`` say it).
    sequence, camera, frame
        Panoptic ids of the row ("" / -1 when the table has none); the camera and frame are also
        parsed from a toolbox name such as ``hdImgs/00_08/00_08_00001147.jpg``.

    Returns
    -------
    str or None
        The first existing candidate: see the module docstring for the order.
    """
    root = Path(root)
    cands = [c for layout in IMAGE_LAYOUTS.values() for c in layout(root, image, sequence, camera, frame)]
    for c in cands:
        try:
            if c.is_file():
                return str(c)
        except OSError:  # a name too long, a permission problem: not this candidate
            continue
    return None


def _view_of(image, camera, frame):
    view = panoptic_view(image) if image else None
    if view is not None:
        return view
    if camera and _CAM_RE.match(str(camera)) and frame is not None and int(frame) >= 0:
        return camera_type(str(camera)), str(camera), int(frame)
    return None


def video_path(root, sequence, camera, kind: str = ""):
    """The camera's video (``hdVideos/hd_00_XX.mp4``, ``vgaVideos/vga_XX_XX.mp4``, ``kinectVideos/kinect_50_XX.mp4``)
    under ``root`` or ``root/sequence``, or None."""
    if not camera or not _CAM_RE.match(str(camera)):
        return None
    kind = kind or camera_type(str(camera))
    _, vid_dir, prefix = _PANOPTIC[kind]
    for b in _bases(root, sequence):
        v = b / vid_dir / f"{prefix}{camera}.mp4"
        if v.is_file():
            return str(v)
    return None


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
        seg = int.from_bytes(data[i + 2 : i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            h = int.from_bytes(data[i + 5 : i + 7], "big")
            w = int.from_bytes(data[i + 7 : i + 9], "big")
            return (w, h) if w > 0 and h > 0 else None
        i += 2 + seg
    return None


def read_image(path, flags=None):
    """BGR image or None; read as bytes first (OpenCV's own file functions cannot take non-UTF-8 names)."""
    import cv2

    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError:
        return None
    if data.size == 0:
        return None
    try:
        return cv2.imdecode(data, cv2.IMREAD_COLOR if flags is None else flags)
    except cv2.error:
        return None


@dataclass(frozen=True)
class ImageRef:
    """Where a row's pixels are: an image file, or frame ``frame`` of a video."""

    path: str | None = None
    video: str | None = None
    frame: int = -1

    @property
    def key(self) -> str:
        """One string per distinct picture (file, or video#frame)."""
        return self.path if self.path is not None else f"{self.video}#{self.frame}"

    def __str__(self) -> str:
        return self.path if self.path is not None else f"{self.video} frame {self.frame}"


class ImageResolver:
    """Resolve rows to pictures under one root and read them.

    Parameters
    ----------
    root : str or Path
        The image root (``--images``).

    Examples
    --------
    >>> r = ImageResolver("/data/panoptic_160906_pizza1")  # doctest: +SKIP
    >>> r.find("hdImgs/00_08/00_08_00001147.jpg")  # doctest: +SKIP
    ImageRef(path='/data/panoptic_160906_pizza1/hdImgs/hd_00_08/00001147.jpg', video=None, frame=-1)
    """

    def __init__(self, root):
        self.root = Path(root)

    def find(self, image, sequence="", camera="", frame=-1):
        """An :class:`ImageRef` for the row, or None when neither a file nor a video frame exists."""
        image = "" if image is None else str(image)
        found = resolve_image(self.root, image, sequence or "", camera or "", -1 if frame is None else frame)
        if found is not None:
            return ImageRef(path=found)
        view = _view_of(image, camera, frame)
        if view is not None:
            kind, cam, fr = view
            v = video_path(self.root, sequence or "", cam, kind)
            if v is not None:
                return ImageRef(video=v, frame=fr)
        return None

    def tried(self, image, sequence="") -> str:
        """Where :meth:`find` looked, for a message."""
        return str(_name_candidates(self.root, str(image or ""), sequence or "")[0]) if image else str(self.root)

    @staticmethod
    def read(refs, flags=None):
        """Yield ``(index, image or None, reason)`` for each ref of ``refs`` (a list): the one way draw, the
        audit page and augment read pictures.

        Image files come in the given order (read with ``cv2.imdecode`` ``flags``, default colour BGR); the
        frames of each video follow, grouped so each video is decoded once, front to back, whatever the
        order of ``refs`` (:class:`hpe_cli.datasets.panoptic_video.VideoFrames`). One picture is in memory
        at a time when the caller consumes them one by one.
        """
        videos: dict = {}
        for i, ref in enumerate(refs):
            if ref.path is not None:
                img = read_image(ref.path, flags)
                yield i, img, "" if img is not None else f"not a readable image: {ref.path}"
            else:
                videos.setdefault(ref.video, {}).setdefault(ref.frame, []).append(i)
        for video, frames in videos.items():
            from ..datasets.panoptic_video import VideoFrames  # lazy: start-up

            for fr, img, reason in VideoFrames(video).read(sorted(frames)):
                for i in frames.get(fr, []):
                    yield i, img, "" if img is not None else f"no image (video {video} frame {fr}: {reason})"


def image_size(ref):
    """``(width, height)`` of a picture without decoding it when possible (JPEG/PNG headers), or None."""
    if ref.path is None:
        import cv2

        cap = cv2.VideoCapture(ref.video)
        try:
            if not cap.isOpened():
                return None
            w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            return (w, h) if w > 0 and h > 0 else None
        finally:
            cap.release()
    try:
        with open(ref.path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return None
    size = jpeg_size(head)
    if size is None and head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) >= 24:
        size = (int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big"))
    if size is None:
        img = read_image(ref.path, flags=-1)
        size = None if img is None else (img.shape[1], img.shape[0])
    return size


def row_ids(frame):
    """``(sequence, camera, frame)`` per row of a pandas frame (``""`` / -1 where the table has none)."""
    import pandas as pd

    n = len(frame)

    def text(col):
        if col not in frame.columns:
            return [""] * n
        return ["" if v is None or pd.isna(v) else str(v) for v in frame[col].tolist()]

    frames = (
        pd.to_numeric(frame["frame"], errors="coerce").fillna(-1).astype(np.int64).tolist()
        if "frame" in frame.columns
        else [-1] * n
    )
    return text("sequence"), text("camera"), frames


__all__ = [
    "IMAGE_COLUMNS",
    "IMAGE_SUFFIXES",
    "ImageRef",
    "ImageResolver",
    "camera_type",
    "image_size",
    "jpeg_size",
    "panoptic_view",
    "read_image",
    "resolve_image",
    "row_ids",
    "video_path",
]
