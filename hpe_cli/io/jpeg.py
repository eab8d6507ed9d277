"""Decode images to OpenCV's exact pixels, JPEGs through libjpeg-turbo's SIMD decoder when it is installed.

``cv2.imread``/``cv2.imdecode`` decode JPEGs with the libjpeg-turbo that OpenCV bundles; ``simplejpeg``
(the ``torch`` extra) wraps a SIMD build of the same library and decodes the AFLW2000-3D and Panoptic frames
about twice as fast, to the same bytes (checked on the real samples in ``tests/io/test_jpeg.py``). The fast
path is taken only where the pixels must be OpenCV's:

* the data is a baseline or progressive JPEG that ``simplejpeg`` decodes (others, and any error, go to OpenCV);
* it carries no EXIF orientation other than 1 (OpenCV turns the pixels by it; ``simplejpeg`` does not);
* the first JPEG this process decodes is decoded both ways and compared: if they differ in one byte, every
  later image goes to OpenCV (:func:`fast_decoder` says which decoder is in use).
"""

from __future__ import annotations

import numpy as np

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
    return cv2.imdecode(buf, flag) if buf.size else None


def fast_decoder() -> str:
    """``"simplejpeg"`` while JPEGs go through it in this process, else ``"opencv"``."""
    return "simplejpeg" if _simplejpeg() is not None and _STATE.get("same", True) else "opencv"


def decode_image(data, rgb: bool = True):
    """uint8 ``(H, W, 3)`` pixels of encoded ``data`` (bytes or a uint8 array), exactly as ``cv2.imdecode``
    with ``IMREAD_COLOR_RGB`` (``rgb``) or ``IMREAD_COLOR`` gives them, or None when it cannot decode them."""
    raw = data.tobytes() if isinstance(data, np.ndarray) else bytes(data)
    sj = _simplejpeg()
    if sj is None or not _STATE.get("same", True) or raw[:2] != b"\xff\xd8" or _orientation(raw) != 1:
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


def read_image(path, rgb: bool = True):
    """:func:`decode_image` of a file's bytes, or None when it cannot be read or decoded (as ``cv2.imread``)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None
    return decode_image(data, rgb) if data else None
