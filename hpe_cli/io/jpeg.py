"""Decode images (or one rectangle of them) to OpenCV's exact pixels, doing less work where it can.

``cv2.imread``/``cv2.imdecode`` decode JPEGs with the libjpeg-turbo that OpenCV bundles; ``simplejpeg``
(the ``torch`` extra) wraps a SIMD build of the same library and decodes the AFLW2000-3D and Panoptic frames
about twice as fast, to the same bytes (checked on the real samples in ``tests/io/test_jpeg.py``). The fast
path is taken only where the pixels must be OpenCV's:

* the data is a baseline or progressive JPEG that ``simplejpeg`` decodes (others, and any error, go to OpenCV);
* it carries no EXIF orientation other than 1 (OpenCV turns the pixels by it; ``simplejpeg`` does not);
* the first JPEG this process decodes is decoded both ways and compared: if they differ in one byte, every
  later image goes to OpenCV (:func:`fast_decoder` says which decoder is in use).

:func:`decode_crop` returns one rectangle of a frame (a training crop), :func:`decode_band` the part of a
frame that several crops need. With ``_hpe_jpeg``, a small C module over the system's libjpeg-turbo built
with the package when its headers are there (``setup.py``), the rows above the rectangle are only
entropy-decoded, the columns beside it are not transformed and decoding stops at its last row: 1.15-1.8x
faster than simplejpeg's whole decode on the AFLW2000-3D crops, 2-3x on Panoptic's HD frames. The same
conditions hold (plain 8-bit YCbCr JPEG, orientation 1, any libjpeg warning sends the image to OpenCV), and
the first rectangle of each process is compared with OpenCV's whole-frame decode (:func:`region_decoder`
says whether it is in use).
"""

from __future__ import annotations

import numpy as np

from ..geometry.crop import crop_padded

_STATE: dict = {}


def _simplejpeg():
    if "module" not in _STATE:
        try:
            import simplejpeg
        except ImportError:  # the torch extra is not installed: OpenCV decodes everything
            simplejpeg = None
        _STATE["module"] = simplejpeg
    return _STATE["module"]


def _orientation(data: bytes) -> int:
    """The EXIF orientation of a JPEG (1 when it has none), read from the APP1 segments before the scan."""
    sos = data.find(b"\xff\xda")
    if b"Exif\x00\x00" not in (data[:sos] if sos > 0 else data):  # the usual frame: one C search, no walk
        return 1
    i, n = 2, len(data)
    while i + 4 <= n and data[i] == 0xFF:
        marker = data[i + 1]
        if marker == 0xDA:  # start of scan: no more metadata
            break
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:
            i += 2
            continue
        size = (data[i + 2] << 8) | data[i + 3]
        if marker == 0xE1 and data[i + 4 : i + 10] == b"Exif\x00\x00":
            return _tiff_orientation(data[i + 10 : i + 2 + size])
        i += 2 + size
    return 1


def _upright_jpeg(raw: bytes) -> bool:
    """A JPEG (``FF D8`` first) with no EXIF orientation other than 1: one whose pixels OpenCV does not turn."""
    return raw[:2] == b"\xff\xd8" and _orientation(raw) == 1


def _bytes(data) -> bytes:
    return data.tobytes() if isinstance(data, np.ndarray) else bytes(data)


def _tiff_orientation(t: bytes) -> int:
    if len(t) < 8 or t[:2] not in (b"II", b"MM"):
        return 0  # unreadable EXIF: let OpenCV decide
    order = "little" if t[:2] == b"II" else "big"
    ifd = int.from_bytes(t[4:8], order)
    if ifd + 2 > len(t):
        return 0
    for k in range(int.from_bytes(t[ifd : ifd + 2], order)):
        e = ifd + 2 + 12 * k
        if e + 12 > len(t):
            return 0
        if int.from_bytes(t[e : e + 2], order) == 0x0112:
            return int.from_bytes(t[e + 8 : e + 10], order)
    return 1


def _cv2(data, rgb: bool):
    import cv2

    flag = getattr(cv2, "IMREAD_COLOR_RGB", None) if rgb else cv2.IMREAD_COLOR
    if flag is None:
        raise ValueError("expected OpenCV >= 4.10 for RGB decoding (cv2.IMREAD_COLOR_RGB)")
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else data
    try:
        return cv2.imdecode(buf, flag) if buf.size else None
    except cv2.error:  # OpenCV asserts instead of returning None on some inputs (a frame over its pixel limit)
        return None


def fast_decoder() -> str:
    """``"simplejpeg"`` while JPEGs go through it in this process, else ``"opencv"``."""
    return "simplejpeg" if _simplejpeg() is not None and _STATE.get("same", True) else "opencv"


def decode_image(data, rgb: bool = True):
    """uint8 ``(H, W, 3)`` pixels of encoded ``data`` (bytes or a uint8 array), exactly as ``cv2.imdecode``
    with ``IMREAD_COLOR_RGB`` (``rgb``) or ``IMREAD_COLOR`` gives them, or None when it cannot decode them."""
    raw = _bytes(data)
    sj = _simplejpeg()
    if sj is None or not _STATE.get("same", True) or not _upright_jpeg(raw):
        return _cv2(data, rgb)
    try:
        img = sj.decode_jpeg(raw, colorspace="RGB" if rgb else "BGR")
    except Exception:  # noqa: BLE001 - lossless, 12-bit, CMYK, damaged: OpenCV decides (and names the failure)
        return _cv2(data, rgb)
    if "same" not in _STATE:  # the first JPEG of this process: both decoders, compared byte for byte
        ref = _cv2(data, rgb)
        _STATE["same"] = ref is not None and ref.shape == img.shape and bool(np.array_equal(ref, img))
        return ref
    return img


def _region():
    if "region" not in _STATE:
        try:
            import _hpe_jpeg
        except ImportError:  # built without libjpeg-turbo's headers or a C compiler: whole frames
            _hpe_jpeg = None
        _STATE["region"] = _hpe_jpeg
    return _STATE["region"] if _STATE.get("region_same", True) else None


def region_decoder() -> str | None:
    """``"libjpeg-turbo"`` while :func:`decode_crop` decodes JPEG rectangles itself in this process, else None."""
    return "libjpeg-turbo" if _region() is not None else None


def _read(path):
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError:
        return None


def decode_band(data, box, rgb: bool = True):
    """The part of the integer box ``(x0, y0, x1, y1)`` inside the frame, decoded over that part only:
    ``(pixels, (top, left), (H, W))`` with ``pixels`` exactly ``cv2.imdecode(data)[top:..., left:...]``, or
    None when ``_hpe_jpeg`` is not built or in use, or declines the data (then decode the whole frame).

    ``pixels`` is a view of a band a little larger than the box; ``(H, W)`` is the whole frame's size.
    """
    mod = _region()
    x0, y0, x1, y1 = (int(v) for v in box)
    if mod is None or x1 <= x0 or y1 <= y0 or max(abs(x0), abs(y0), abs(x1), abs(y1)) >= 1 << 30:
        return None  # (a box beyond C int range: the whole-frame path crops it)
    raw = _bytes(data)
    if not _upright_jpeg(raw):
        return None
    got = mod.decode_region(raw, y0, x0, y1, x1, rgb)
    if got is None:
        return None
    band, rows, stride, H, W, ry, rx, dy, dx = got
    pix = np.frombuffer(band, np.uint8).reshape(rows, stride // 3, 3)
    pix = pix[dy : dy + min(y1, H) - ry, dx : dx + min(x1, W) - rx]
    if "region_same" not in _STATE:  # the first rectangle of this process, against OpenCV's whole frame
        ref = _cv2(raw, rgb)
        ref = None if ref is None else ref[ry : ry + pix.shape[0], rx : rx + pix.shape[1]]
        _STATE["region_same"] = ref is not None and ref.shape == pix.shape and bool(np.array_equal(ref, pix))
        if not _STATE["region_same"]:
            return None
    return pix, (ry, rx), (H, W)


def crop_band(band, box, value=0):
    """The pixels of the integer box ``(x0, y0, x1, y1)`` from a :func:`decode_band` result, ``value`` outside
    the frame: what :func:`~hpe_cli.geometry.crop.crop_padded` gives on the whole frame, for any box inside the
    decoded part (a view when the box lies inside the frame)."""
    pix, (top, left), (H, W) = band
    x0, y0, x1, y1 = (int(v) for v in box)
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
    bottom, right = top + pix.shape[0], left + pix.shape[1]
    if sx1 > sx0 and sy1 > sy0 and not (top <= sy0 and left <= sx0 and sy1 <= bottom and sx1 <= right):
        raise ValueError(f"expected a box inside the decoded part {left, top, right, bottom}, got {box}")
    # the box's part inside the frame lies inside the band: outside the band is outside the frame
    return crop_padded(pix, (x0 - left, y0 - top, x1 - left, y1 - top), value)


def decode_crop(data, box, rgb: bool = True):
    """The pixels of the integer box ``(x0, y0, x1, y1)`` (ends exclusive) of encoded ``data``, zeros outside the
    frame: exactly ``crop_padded(decode_image(data, rgb), box)``, or None when the data cannot be decoded.

    JPEGs are decoded over the box only (:func:`decode_band`) when ``_hpe_jpeg`` is built and in use.
    """
    raw = _bytes(data)
    band = decode_band(raw, box, rgb)
    if band is not None:
        return crop_band(band, box)
    img = decode_image(raw, rgb)
    return None if img is None else crop_padded(img, box)


def read_crop(path, box, rgb: bool = True):
    """:func:`decode_crop` of a file's bytes, or None when it cannot be read or decoded."""
    data = _read(path)
    return decode_crop(data, box, rgb) if data else None


def read_image(path, rgb: bool = True):
    """:func:`decode_image` of a file's bytes, or None when it cannot be read or decoded (as ``cv2.imread``)."""
    data = _read(path)
    return decode_image(data, rgb) if data else None
