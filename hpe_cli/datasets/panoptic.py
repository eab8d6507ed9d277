"""CMU Panoptic Studio readers: calibration and ``hdFace3d`` frames (SPEC §6).

Pure functions returning numpy arrays; they never print. Unknown JSON fields
are ignored, so face files of version 0.5 and 0.7 (which adds ``univTime``
and ``fpsType``) both parse. Problems in a file raise
:class:`~hpe_cli.errors.HpeError` naming the file and the record.

Layout of a sequence folder ``<seq>/``::

    calibration_<seq>.json
    hdFace3d/faceRecon3D_hd%08d.json     (or hdFace3d.tar, read member by member)
    hdImgs/<cam>/<cam>_%08d.jpg          (images, optional; panoptic-toolbox's
                                          scripts/hdImgsExtractor.sh numbers them from 0)
    hdVideos/hd_00_XX.mp4                (the videos; see panoptic_video.py)
"""

from __future__ import annotations

import os
import re
import tarfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import HpeError
from .fields import as_int, describe, frame_number_problem, member_problem
from .panoptic_calibration import (  # noqa: F401
    ABSURD,
    CAMERA_TYPES,
    NAME_RE,
    Cameras,
    read_calibration,
)

# the calibration reader lives in panoptic_calibration.py; its names are part of this module's API
from .panoptic_json import load_panoptic_json, parse_panoptic_json  # noqa: F401

FACE_DIR = "hdFace3d"
FACE_RE = re.compile(r"^faceRecon3D_hd(\d+)\.json$")
FACE_TAR = "hdFace3d.tar"
N_FACE70 = 70
#: image folder of each camera type in Panoptic's layout
IMAGE_DIRS = {"hd": "hdImgs", "vga": "vgaImgs", "kinect-color": "kinectImgs"}


@dataclass(frozen=True)
class FaceRef:
    """Where one frame's face JSON is: a file, or a member of ``hdFace3d.tar``.

    Picklable and small, so worker processes (or Dask workers) open the
    file themselves. ``truncated`` marks a tar member whose data is cut short.
    """

    path: str
    member: str = ""
    offset: int = -1
    size: int = -1
    truncated: bool = False

    @property
    def name(self) -> str:
        """The name used in messages: the file, or ``tar:member``."""
        return f"{self.path}:{self.member}" if self.member else self.path

    def read_text(self) -> str:
        return self.read_bytes().decode("utf-8")

    def read_bytes(self) -> bytes:
        if not self.member:
            with open(self.path, "rb") as fh:
                return fh.read()
        with open(self.path, "rb") as fh:
            fh.seek(self.offset)
            data = fh.read(self.size)
        if len(data) != self.size:
            raise HpeError(f"{self.name}: truncated member ({len(data)} of {self.size} bytes)")
        return data


def face_frames(seq_dir) -> dict:
    """Face files of a sequence by frame number: ``{frame: Path}``, sorted.

    ``seq_dir`` is the sequence folder (with ``hdFace3d/``) or the
    ``hdFace3d`` folder itself. Frame numbers come from the file names, so
    gaps are allowed; other files are ignored. Two files with the same frame
    number (``faceRecon3D_hd00001147.json`` and ``faceRecon3D_hd1147.json``)
    are an error naming both.
    """
    seq_dir = Path(seq_dir)
    face_dir = seq_dir / FACE_DIR if (seq_dir / FACE_DIR).is_dir() else seq_dir
    frames: dict = {}
    if face_dir.is_dir():
        for p in sorted(face_dir.iterdir()):
            m = FACE_RE.match(p.name)
            if m and p.is_file():
                if frame_number_problem(m.group(1)):
                    raise HpeError(f"{p}: {frame_number_problem(m.group(1))}")
                k = int(m.group(1))
                if k in frames:
                    raise HpeError(f"{frames[k]} and {p}: both are frame {k}; keep one of them")
                frames[k] = p
    if not frames and face_dir == seq_dir and seq_dir.name != FACE_DIR:
        raise HpeError(f"{seq_dir}: no {FACE_DIR}/ folder")
    return dict(sorted(frames.items()))


def tar_frames(tar_path) -> dict:
    """Members of ``hdFace3d.tar`` by frame number: ``{frame: FaceRef}``, sorted.

    The archive is indexed once (headers only, nothing is extracted); the
    JSON of a frame is read later from its offset. Members are matched by
    base name (``hdFace3d/faceRecon3D_hd00000123.json``); two members with
    the same frame number are an error naming both. A member whose data is
    cut short (a truncated download) is kept with ``truncated=True`` (the
    job rejects that frame); a tar whose headers are unreadable before any
    member is an error.

    A plain, intact archive is indexed by :func:`_scan_plain_tar` (its
    headers about 9x faster than :mod:`tarfile` reads them; see
    ``benchmarks/tar_index.py``); anything else (pax or GNU long-name records,
    a damaged or truncated download, duplicate frames) goes through
    :mod:`tarfile` (:func:`_tar_frames_tarfile`), which gives the same result
    and every error message.
    """
    fast = _tar_frames_fast(tar_path)
    return fast if fast is not None else _tar_frames_tarfile(tar_path)


def _tar_frames_fast(tar_path):
    """:func:`tar_frames` from :func:`_scan_plain_tar`, or None where tarfile must decide."""
    tar_path = Path(tar_path)
    members = _scan_plain_tar(tar_path)
    if members is None:
        return None
    frames: dict = {}
    path = str(tar_path)
    match = FACE_RE.match
    for name, is_dir, offset, size in members:
        if member_problem(name):
            return None  # _tar_frames_tarfile refuses it with the message
        if not is_dir:
            m = match(name[name.rfind("/") + 1 :])  # the base name, as _tar_frames_tarfile matches it
            if m:
                if frame_number_problem(m[1]):
                    return None
                k = int(m[1])
                if k in frames:
                    return None  # tarfile's path names both members
                # never truncated: the scanner only accepts end blocks after all member data
                frames[k] = FaceRef(path, name, offset, size, False)
    return dict(sorted(frames.items()))


#: typeflags of the plain case: regular file ("0", or NUL in old tars) and directory ("5")
_FILE, _OLD_FILE, _DIR = ord("0"), 0, ord("5")
#: magic + version of a POSIX ustar header and of a GNU tar header, as 8-byte words
_MAGICS = np.frombuffer(b"ustar\x0000ustar  \x00", dtype=np.uint64)
#: where the header's number fields (all those tarfile reads, TarInfo.frombuf) start when bytes
#: 100:156 (mode uid gid size mtime chksum) and 329:345 (devmajor devminor) are put side by side
_FIELD_STARTS = np.array([8, 16, 24, 36, 48, 56, 64])
_BLOCK = 512
_ZERO_BLOCK = bytes(_BLOCK)


def _scan_plain_tar(path, chunk: int = 4096):
    """Every member of a plain ustar or GNU tar, from its headers, or None to let tarfile decide.

    The layout follows the ustar format description of POSIX.1 (``pax``,
    "ustar Interchange Format") and GNU tar's manual ("Basic Tar Format",
    ``tar.h``): 512-byte blocks; a header holds ``name[0:100]``, octal
    numbers ``mode uid gid size[124:136] mtime chksum[148:156]``,
    ``typeflag[156]``, ``magic[257:265]`` (``"ustar\\0" "00"`` or GNU's
    ``"ustar  \\0"``), ``devmajor devminor`` and the ustar
    ``prefix[345:500]``; member data follows, padded to whole blocks; the
    archive ends with zero blocks. Names and numbers are read the way
    CPython's ``tarfile`` reads them (``TarInfo.frombuf``, ``nti``, ``nts``,
    ``_proc_builtin``: names in ``tarfile.ENCODING`` with ``surrogateescape``,
    a non-empty prefix joined with ``/``, trailing ``/`` of directories
    removed), so the result equals ``tarfile``'s for every archive accepted.

    Only the plain case is accepted: regular files (typeflag ``0`` or NUL),
    empty directories (``5``), ustar or GNU magic, numbers written as
    octal digits then spaces or NULs (as tarfile, GNU tar and bsdtar write
    them), right checksums (unsigned, or signed as some old tars summed), and,
    after the last member's data, a zero block with nothing but zeros after
    it. Anything else returns None: pax (``x``/``g``) and GNU long-name
    (``L``/``K``) records, sparse files, links, base-256 numbers or ones with
    leading spaces, a damaged header, an archive cut short, not a tar at all.

    Each header is one 512-byte ``os.pread`` (the walk needs each size to
    find the next header; member data is never read; as fast as a memory map
    here, and safe if the file shrinks meanwhile); checksums and number
    fields are checked with numpy, ``chunk`` headers at a time. Without
    ``os.pread`` (Windows) it returns None.

    Parameters
    ----------
    path : str or Path
    chunk : int
        Headers checked per numpy batch (memory: about ``chunk`` KB).

    Returns
    -------
    list of (str, bool, int, int) or None
        ``(name, is_dir, offset_data, size)`` per member in archive order:
        the name as tarfile decodes it, whether it is a directory, the byte
        offset of its data, its size in bytes.
    """
    pread = getattr(os, "pread", None)
    if pread is None:  # not on Windows: tarfile reads it
        return None
    members: list = []
    heads: list = []
    enc = tarfile.ENCODING
    off = 0
    try:
        with open(path, "rb", buffering=0) as fh:
            fd, n = fh.fileno(), os.fstat(fh.fileno()).st_size
            while True:
                head = pread(fd, _BLOCK, off) if off + _BLOCK <= n else b""
                if len(head) != _BLOCK:
                    return None  # cut inside a header or member data, or no end-of-archive block
                if head == _ZERO_BLOCK:
                    break
                try:
                    size = int(head[124:136].rstrip(b" \0") or b"0", 8)  # _plain_headers checks the digits
                except ValueError:
                    return None
                kind = head[156]
                if size < 0 or kind not in (_FILE, _OLD_FILE, _DIR):
                    return None
                i = head.find(0, 0, 100)
                name = head[: i if i >= 0 else 100].decode(enc, "surrogateescape")
                is_dir = kind == _DIR or (kind == _OLD_FILE and name.endswith("/"))  # V7: a file "x/" is a dir
                if is_dir:
                    if size:
                        return None  # tarfile does not skip a directory's data
                    name = name.rstrip("/")
                if head[345]:  # a ustar prefix (tarfile joins GNU headers' bytes 345:500 too)
                    i = head.find(0, 345, 500)
                    name = head[345 : i if i >= 0 else 500].decode(enc, "surrogateescape") + "/" + name
                    if is_dir:
                        name = name.rstrip("/")
                members.append((name, is_dir, off + _BLOCK, size))
                heads.append(head)
                off += _BLOCK + (size + _BLOCK - 1) // _BLOCK * _BLOCK
                if len(heads) == chunk:
                    if not _plain_headers(heads):
                        return None
                    heads = []
    except OSError:
        return None
    if heads and not _plain_headers(heads):
        return None
    if _nonzero_after(path, off):
        return None  # something after the end block: tarfile's path reports it
    return members


def _plain_headers(heads: list) -> bool:
    """True if every header has plain octal numbers, ustar or GNU magic and a right
    checksum (see :func:`_scan_plain_tar`)."""
    h = np.frombuffer(b"".join(heads), dtype=np.uint8).reshape(len(heads), _BLOCK)
    num = np.concatenate([h[:, 100:156], h[:, 329:345]], axis=1)  # every number field, side by side
    digit = (num >= ord("0")) & (num <= ord("7"))
    end = (num == 0) | (num == ord(" "))
    # tarfile's nti reads a field of digits then spaces/NULs as those digits (nothing is 0), as
    # the walk read the size; a digit after a space/NUL of its field, or any other byte, is not plain
    pair = end[:, :-1] & digit[:, 1:]
    pair[:, _FIELD_STARTS - 1] = False  # pairs across two fields
    if (~(digit | end)).any() or pair.any():
        return False
    magic = np.ascontiguousarray(h[:, 257:265]).view(np.uint64)[:, 0]
    if not np.isin(magic, _MAGICS).all():
        return False
    chk = np.zeros(len(h), dtype=np.int64)
    for j in range(148, 156):
        chk = np.where(digit[:, j - 100], chk * 8 + h[:, j] - ord("0"), chk)
    rest = h.sum(axis=1, dtype=np.uint32).astype(np.int64) - h[:, 148:156].sum(axis=1, dtype=np.int64)
    good = chk == rest + 8 * ord(" ")  # the chksum field counts as 8 spaces
    if not good.all():  # some old tars summed signed bytes; tarfile accepts both sums
        signed = h.view(np.int8)
        good |= chk == (
            signed.sum(axis=1, dtype=np.int64) - signed[:, 148:156].sum(axis=1, dtype=np.int64) + 8 * ord(" ")
        )
    return bool(good.all())


def _tar_frames_tarfile(tar_path) -> dict:
    """:func:`tar_frames` with the stdlib :mod:`tarfile` (any archive, every fault reported)."""
    tar_path = Path(tar_path)
    frames: dict = {}
    try:
        size = tar_path.stat().st_size
        with tarfile.open(tar_path, "r:") as tf:
            while True:
                try:
                    info = tf.next()
                except tarfile.ReadError as exc:
                    if not frames:
                        raise HpeError(f"{tar_path}: not a readable tar archive ({exc})") from None
                    if size - tf.offset >= tarfile.BLOCKSIZE:  # a whole header is there but unreadable
                        raise HpeError(
                            f"{tar_path}: unreadable member header at byte {tf.offset} ({exc}); "
                            "the frames after it cannot be found (corrupt download?)"
                        ) from None
                    break  # cut inside the last header: the members before it are indexed
                if info is None:  # end of the archive, or a header tarfile cannot read
                    if size - tf.offset < tarfile.BLOCKSIZE and _nonzero_after(tar_path, tf.offset):
                        raise HpeError(
                            f"{tar_path}: the archive ends inside a member header at byte {tf.offset} "
                            "(truncated download); the frames after it cannot be found"
                        )
                    if _nonzero_after(tar_path, tf.offset):
                        raise HpeError(
                            f"{tar_path}: unreadable member header at byte {tf.offset}; the frames "
                            "after it cannot be found (corrupt download?)"
                        )
                    if tf.offset == size and frames and not any(r.truncated for r in frames.values()):
                        raise HpeError(
                            f"{tar_path}: ends at byte {size} without tar's end-of-archive blocks "
                            "(truncated download?); frames after the last member may be missing"
                        )
                    break
                if member_problem(info.name):
                    raise HpeError(f"{tar_path}: member {info.name!r}: refused: {member_problem(info.name)}")
                if not info.isfile():
                    continue
                m = FACE_RE.match(info.name.rsplit("/", 1)[-1])
                if not m:
                    continue
                if frame_number_problem(m.group(1)):
                    raise HpeError(f"{tar_path}: member {info.name}: {frame_number_problem(m.group(1))}")
                k = int(m.group(1))
                if k in frames:
                    raise HpeError(f"{tar_path}: members {frames[k].member} and {info.name} are both frame {k}")
                frames[k] = FaceRef(
                    str(tar_path), info.name, info.offset_data, info.size, info.offset_data + info.size > size
                )
    except tarfile.ReadError as exc:
        raise HpeError(f"{tar_path}: not a readable tar archive ({exc})") from None
    except OSError as exc:
        raise HpeError(f"{tar_path}: cannot read ({exc.strerror or exc})") from None
    return dict(sorted(frames.items()))


def _nonzero_after(path, offset: int) -> bool:
    """True if the file has a non-zero byte at or after ``offset`` (a tar ends in zero blocks)."""
    with open(path, "rb") as fh:
        fh.seek(offset)
        while True:
            block = fh.read(1 << 20)
            if not block:
                return False
            if block.count(0) != len(block):
                return True


def face_sources(seq_dir) -> dict:
    """A sequence's face frames as ``{frame: FaceRef}``: from ``hdFace3d/`` if it
    holds face files, else from ``hdFace3d.tar`` (read in place)."""
    seq_dir = Path(seq_dir)
    if (seq_dir / FACE_DIR).is_dir():
        found = face_frames(seq_dir)
        if found or not (seq_dir / FACE_TAR).is_file():
            return {k: FaceRef(str(p)) for k, p in found.items()}
    if (seq_dir / FACE_TAR).is_file():
        return tar_frames(seq_dir / FACE_TAR)
    if seq_dir.name == FACE_DIR:
        return {k: FaceRef(str(p)) for k, p in face_frames(seq_dir).items()}
    raise HpeError(f"{seq_dir}: no {FACE_DIR}/ folder and no {FACE_TAR}")


def is_sequence(path) -> bool:
    """True if ``path`` looks like a Panoptic sequence folder (faces and a calibration)."""
    path = Path(path)
    return ((path / FACE_DIR).is_dir() or (path / FACE_TAR).is_file()) and any(path.glob("calibration_*.json"))


def hd_image_path(seq_root, camera: str, frame: int) -> Path:
    """The ``hdImgs`` image of ``camera`` at HD frame ``frame``.

    panoptic-toolbox's ``scripts/hdImgsExtractor.sh`` writes
    ``hdImgs/00_XX/00_XX_%08d.jpg`` (``ffmpeg -start_number 0``: image k is
    video frame k, the HD frame number). Some mirrors store
    ``hdImgs/hd_00_XX/%08d.jpg``; that layout is used when only it exists.
    """
    if not NAME_RE.match(str(camera)) or camera in (".", ".."):
        raise HpeError(f"expected a camera name of letters, digits, '_', '-' or '.', got {camera!r}")
    root = Path(seq_root) / IMAGE_DIRS["hd"]
    main = root / camera / f"{camera}_{int(frame):08d}.jpg"
    if not main.exists():
        alt = root / f"hd_{camera}" / f"{int(frame):08d}.jpg"
        if alt.exists():
            return alt
    return main


def hd_video_path(seq_root, camera: str) -> Path:
    """``hdVideos/hd_00_XX.mp4`` of an HD camera named ``00_XX``."""
    return Path(seq_root) / "hdVideos" / f"hd_{camera}.mp4"


def read_face_frame(path) -> dict:
    """Read one ``faceRecon3D_hd%08d.json``.

    Returns
    -------
    dict
        ``frame`` (int, from the file name, or -1), ``version``, ``univTime``
        (float or NaN), ``person_id`` (P,) int, ``landmarks`` (P, 70, 3)
        world cm (NaN where the file has null/NaN), ``score`` (P, 70)
        ``averageScore``, ``reproj_error`` (P, 70) ``averageReproError``
        (NaN when absent).
    """
    if isinstance(path, FaceRef):
        data = parse_panoptic_json(path.read_bytes(), path.name)
        m = FACE_RE.match((path.member or path.path).replace("\\", "/").rsplit("/", 1)[-1])
        path = path.name
    else:
        path = Path(path)
        data = load_panoptic_json(path)
        m = FACE_RE.match(path.name)
    if not isinstance(data, dict) or not isinstance(data.get("people"), list):
        raise HpeError(f"{path}: expected an object with a 'people' list")
    people = data["people"]
    n = len(people)
    ids = np.empty(n, dtype=np.int64)
    lm = np.empty((n, N_FACE70, 3))
    score = np.empty((n, N_FACE70))
    rep = np.full((n, N_FACE70), np.nan)
    for i, person in enumerate(people):
        where = f"{path}: person {i}"
        if not isinstance(person, dict):
            raise HpeError(f"{where}: expected an object with id and face70, got {describe(person)}")
        try:
            pid, why = as_int(person["id"], -(2**63), 2**63 - 1)
            if pid is None:
                raise HpeError(f"{where}: id: expected an integer, {why}")
            ids[i] = pid
            where = f"{path}: person {i} (id {ids[i]})"
            face = person["face70"]
            if not isinstance(face, dict):
                raise HpeError(
                    f"{where}: face70: expected an object with landmarks and averageScore, got {describe(face)}"
                )
            lm[i] = _floats(face["landmarks"], 3 * N_FACE70, where, "landmarks").reshape(N_FACE70, 3)
            score[i] = _floats(face["averageScore"], N_FACE70, where, "averageScore")
            if face.get("averageReproError") is not None:
                rep[i] = _floats(face["averageReproError"], N_FACE70, where, "averageReproError")
        except KeyError as exc:
            raise HpeError(f"{where}: missing key {exc.args[0]!r}") from None
    if len(set(ids.tolist())) != n:
        raise HpeError(f"{path}: person ids repeat ({ids.tolist()})")
    t = data.get("univTime")
    if m and frame_number_problem(m.group(1)):
        raise HpeError(f"{path}: {frame_number_problem(m.group(1))}")
    return {
        "frame": int(m.group(1)) if m else -1,
        "version": data.get("version"),
        "univTime": float(t) if isinstance(t, float) or (isinstance(t, int) and abs(t) < 2**53) else float("nan"),
        "person_id": ids,
        "landmarks": lm,
        "score": score,
        "reproj_error": rep,
    }


def read_face_frames(paths: dict) -> dict:
    """Read several frames (``{frame: path}``) into flat per-face arrays.

    Returns
    -------
    dict
        ``frame`` (N,) int, ``person_id`` (N,) int, ``landmarks`` (N, 70, 3),
        ``score`` (N, 70), one row per person per frame, in frame order;
        ``unreadable``: list of ``(frame, reason, detail)`` for tar members
        cut short (their frames are not read).
    """
    parts = []
    unreadable = []
    for frame, p in paths.items():
        if isinstance(p, FaceRef) and p.truncated:
            unreadable.append(
                (int(frame), "truncated face file", f"{p.member}: {p.size} bytes declared, the archive ends first")
            )
            continue
        f = read_face_frame(p)
        parts.append((np.full(len(f["person_id"]), int(frame), dtype=np.int64), f))
    if not parts:
        return {
            "frame": np.zeros(0, np.int64),
            "person_id": np.zeros(0, np.int64),
            "landmarks": np.zeros((0, N_FACE70, 3)),
            "score": np.zeros((0, N_FACE70)),
            "unreadable": unreadable,
        }
    return {
        "unreadable": unreadable,
        "frame": np.concatenate([fr for fr, _ in parts]),
        "person_id": np.concatenate([f["person_id"] for _, f in parts]),
        "landmarks": np.concatenate([f["landmarks"] for _, f in parts]),
        "score": np.concatenate([f["score"] for _, f in parts]),
    }


def image_path(camera: str, frame: int, camera_type: str = "hd") -> str:
    """Panoptic's image path, e.g. ``hdImgs/00_08/00_08_00006577.jpg``."""
    return f"{IMAGE_DIRS.get(camera_type, 'hdImgs')}/{camera}/{camera}_{int(frame):08d}.jpg"


def find_calibration(seq_dir) -> Path:
    """``<seq_dir>/calibration_<seq>.json``, or the only ``calibration_*.json`` there."""
    seq_dir = Path(seq_dir)
    own = seq_dir / f"calibration_{seq_dir.resolve().name}.json"
    if own.is_file():
        return own
    found = sorted(seq_dir.glob("calibration_*.json"))
    if len(found) == 1:
        return found[0]
    if not found:
        raise HpeError(f"{seq_dir}: no calibration_<seq>.json (use --calibration FILE)")
    raise HpeError(
        f"{seq_dir}: several calibration files ({', '.join(p.name for p in found)}); choose one with --calibration FILE"
    )


# ----------------------------------------------------------------- helpers
def _floats(value, n, where, key) -> np.ndarray:
    """A list of ``n`` numbers (null -> NaN); strings, bools, nested lists and objects are refused."""
    if not isinstance(value, list):
        raise HpeError(f"{where}: expected {key} to be a list of {n} numbers, got {describe(value)}")
    if len(value) != n:
        raise HpeError(f"{where}: expected {n} {key} values, got {len(value)}")
    try:
        arr = np.array(value)  # no dtype: strings stay strings, nulls make an object array
    except (ValueError, TypeError, OverflowError, RecursionError):
        arr = None
    if arr is not None and arr.dtype.kind in "fi" and arr.ndim == 1 and not any(type(v) is bool for v in value):
        return arr.astype(np.float64, copy=False)
    for k, v in enumerate(value):  # the slow path finds the culprit (or accepts numbers mixed with nulls)
        if v is not None and (type(v) is bool or not isinstance(v, (int, float))):
            raise HpeError(f"{where}: {key}: expected numbers (or null), got {describe(v)} at index {k}")
    try:
        return np.array([np.nan if v is None else v for v in value], dtype=np.float64)
    except OverflowError:  # an integer beyond float64
        raise HpeError(f"{where}: {key}: expected numbers within float64's range") from None
