"""JPEG decoding takes libjpeg-turbo's SIMD path only where it gives OpenCV's exact pixels."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from hpe_cli.io import jpeg

REAL = Path(__file__).resolve().parents[3] / "shared" / "realdata"
RGB = getattr(cv2, "IMREAD_COLOR_RGB", None)
pytestmark = pytest.mark.skipif(RGB is None, reason="OpenCV < 4.10 has no RGB decoding")


def _jpegs():
    files = sorted(REAL.glob("aflw2000_prnet/*.jpg"))[:8] + sorted(REAL.rglob("*.jpg"))[:40:5]
    return files or pytest.skip("no real JPEG samples")


@pytest.mark.parametrize("rgb", [True, False])
def test_real_jpegs_decode_to_opencvs_bytes(rgb):
    pytest.importorskip("simplejpeg")
    for f in _jpegs():
        want = cv2.imread(str(f), RGB if rgb else cv2.IMREAD_COLOR)
        got = jpeg.read_image(f, rgb)
        assert got.shape == want.shape and np.array_equal(got, want), f
    assert jpeg.fast_decoder() == "simplejpeg"


def _exif(orientation: int, order=b"MM") -> bytes:
    big = order == b"MM"
    i16 = lambda v: v.to_bytes(2, "big" if big else "little")
    i32 = lambda v: v.to_bytes(4, "big" if big else "little")
    tiff = order + i16(42) + i32(8) + i16(1) + i16(0x0112) + i16(3) + i32(1) + i16(orientation) + b"\0\0" + i32(0)
    body = b"Exif\x00\x00" + tiff
    return b"\xff\xe1" + (len(body) + 2).to_bytes(2, "big") + body


@pytest.mark.parametrize("order", [b"MM", b"II"])
def test_exif_orientation_goes_to_opencv(order):
    """A turned JPEG: OpenCV applies the orientation, simplejpeg would not; the pixels are OpenCV's."""
    img = np.zeros((40, 60, 3), np.uint8)
    img[:10, :20] = 255
    ok, enc = cv2.imencode(".jpg", img)
    data = enc.tobytes()
    turned = data[:2] + _exif(6, order) + data[2:]  # orientation 6: rotate 90 degrees clockwise
    assert jpeg._orientation(turned) == 6 and jpeg._orientation(data) == 1
    want = cv2.imdecode(np.frombuffer(turned, np.uint8), RGB)
    got = jpeg.decode_image(turned)
    assert got.shape == want.shape == (60, 40, 3) and np.array_equal(got, want)


def test_not_a_jpeg_and_damaged_data_go_to_opencv():
    img = (np.arange(30 * 20 * 3) % 251).astype(np.uint8).reshape(30, 20, 3)
    ok, png = cv2.imencode(".png", img)
    assert np.array_equal(jpeg.decode_image(png.tobytes(), rgb=False), img)
    assert jpeg.decode_image(b"\xff\xd8\xff\xe0 not really a jpeg") is None
    assert jpeg.read_image("/no/such/file.jpg") is None
