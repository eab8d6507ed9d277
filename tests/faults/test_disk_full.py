"""A full disk while writing pictures: one line saying the device is full and naming the picture's path (not the
table's, not a byte count) (issue 35)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest

from conftest import hpe
from hpe_cli.errors import HpeError
from hpe_cli.io import os_errors
from hpe_cli.io.os_errors import os_reason, write_bytes

ROOT = Path(__file__).resolve().parents[2]
AFLW = ROOT / "sample_data" / "aflw2000"


def test_numpy_short_write_reads_as_disk_full():
    assert os_reason(OSError("81030 requested and 53248 written")) == "disk full (the device took 53248 of 81030 bytes)"
    assert os_reason(OSError(errno.ENOSPC, "No space left on device")) == "disk full (no space left on device)"


def _dev_full() -> bool:
    import stat

    try:
        return stat.S_ISCHR(os.stat("/dev/full").st_mode)  # never create a file there: the device or nothing
    except OSError:
        return False


@pytest.mark.skipif(not _dev_full(), reason="no /dev/full device")
def test_write_bytes_on_a_full_device_names_the_shown_path():
    with pytest.raises(HpeError) as e:
        write_bytes("/dev/full", np.zeros(100_000, np.uint8), "out/imgs/a.jpg")
    assert str(e.value) == "out/imgs/a.jpg: cannot write: disk full (no space left on device)"


def test_augment_out_images_on_a_full_disk(tmp_path, monkeypatch):
    real_open = open

    def full_open(path, mode="r", *a, **k):  # the picture writes find the disk full
        if "w" in mode and str(path).endswith(".jpg"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_open(path, mode, *a, **k)

    monkeypatch.setattr(os_errors, "open", full_open, raising=False)
    out, imgs = tmp_path / "out.parquet", tmp_path / "imgs"
    r = hpe("augment", AFLW, "-o", out, "--hflip", "--images", AFLW, "--out-images", imgs)
    assert r.exit_code == 1
    lines = r.output.strip().splitlines()
    assert len(lines) == 1, r.output
    assert lines[0].startswith(f"Error: {imgs}/image") and lines[0].endswith(
        ".jpg: cannot write: disk full (no space left on device)"
    ), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing written, no temporaries


def test_export_crops_on_a_full_disk_name_the_crop(tmp_path, monkeypatch):
    """export writes its crops through io.os_errors.write_bytes: a full disk names the crop's path in the output
    folder (not the staged name, not a byte count), and nothing is left behind."""
    real_open = open

    def full_open(path, mode="r", *a, **k):
        if "w" in mode and str(path).endswith(".jpg"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_open(path, mode, *a, **k)

    monkeypatch.setattr(os_errors, "open", full_open, raising=False)
    out = tmp_path / "out"
    r = hpe("export", AFLW, "-o", out, "--layout", "6drepnet", "--form", "crops", "--workers", "1")
    assert r.exit_code == 1, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1, r.output
    assert lines[0].startswith(f"Error: {out}/") and lines[0].endswith(
        ".jpg: cannot write: disk full (no space left on device)"
    ), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == []
