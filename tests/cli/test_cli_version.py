"""``hpe --version`` names the optional parts this installation has; ``setup.py`` says whether it built the decoder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import hpe_process
from hpe_cli import __version__

ROOT = Path(__file__).resolve().parents[2]


def _has(module):
    import importlib.util

    return importlib.util.find_spec(module) is not None


def test_version_lists_the_optional_parts():
    p = hpe_process("--version")
    assert p.returncode == 0 and p.stderr == ""
    lines = p.stdout.strip().splitlines()
    assert lines[0].startswith(f"hpe {__version__} (Python ")
    parts = {line.split(":", 1)[0].strip(): line.split(":", 1)[1] for line in lines[1:]}
    assert set(parts) == {
        "region JPEG decoder",
        "column kernels",
        "whole-frame JPEG decoder",
        "torch extra",
        "dask extra",
    }
    # each state agrees with what this interpreter can import (the oracle: importing them here)
    try:
        import _hpe_jpeg  # noqa: F401

        assert parts["region JPEG decoder"].strip().startswith("built ("), parts
    except ImportError:
        assert "not built" in parts["region JPEG decoder"] or "cannot load" in parts["region JPEG decoder"]
    try:
        import _hpe_kernels  # noqa: F401

        assert parts["column kernels"].strip().startswith("built ("), parts
    except ImportError:
        assert "not built" in parts["column kernels"] or "cannot load" in parts["column kernels"]
    assert ("simplejpeg " in parts["whole-frame JPEG decoder"]) == _has("simplejpeg")
    assert ("torch " in parts["torch extra"]) == (_has("torch") and _has("torchvision"))
    assert ("distributed " in parts["dask extra"]) == _has("distributed")


def test_version_says_when_parts_are_missing(tmp_path):
    """An interpreter where the optional modules cannot be found (find_spec and the import are blocked)."""
    e = dict(os.environ, PYTHONPATH=f"{ROOT}")
    code = (
        "import sys, importlib.util as u; sys.path.insert(0, sys.argv[1]);"
        "real = u.find_spec;"
        "u.find_spec = lambda n, *a: None if n.split('.')[0] in "
        "('_hpe_jpeg','_hpe_kernels','simplejpeg','torch','torchvision','distributed') else real(n, *a);"
        "sys.modules['_hpe_jpeg'] = None; sys.modules['_hpe_kernels'] = None;"
        "from hpe_cli.cli.version import version_text; print(version_text())"
    )
    p = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, env=e, timeout=60)
    assert p.returncode == 0, p.stderr
    out = p.stdout
    assert "region JPEG decoder:" in out and "not built: whole frames are decoded" in out
    assert "column kernels:" in out and "not built: their numpy twins run" in out
    assert "OpenCV (simplejpeg not installed" in out
    assert 'torch extra:              not installed (pip install ".[torch]")' in out
    assert 'dask extra:               not installed (pip install ".[dask]")' in out


def test_version_does_not_import_heavy_modules():
    code = (
        "import sys; from hpe_cli.cli.version import version_text; version_text();"
        "print(sorted(m for m in ('torch', 'dask', 'distributed', 'numpy', 'cv2', 'simplejpeg') if m in sys.modules))"
    )
    p = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert p.stdout.strip() == "[]", p.stdout + p.stderr


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
@pytest.mark.parametrize("works", [True, False])
def test_setup_py_says_whether_each_module_was_built(works, tmp_path):
    env = dict(os.environ)
    if not works:
        env["CC"] = "/bin/false"  # a compiler that always fails
    p = subprocess.run(
        [
            sys.executable,
            "setup.py",
            "-q",
            "build_ext",
            "--build-lib",
            str(tmp_path / "lib"),
            "--build-temp",
            str(tmp_path / "tmp"),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    said = [line for line in p.stderr.splitlines() if line.startswith("hpe: ")]
    assert len(said) == 2, p.stderr  # one line per optional module
    jpeg, kern = (next(x for x in said if name in x) for name in ("_hpe_jpeg", "_hpe_kernels"))
    if works and "jpeglib.h" in p.stderr:  # no libjpeg headers here: the build says NOT built, which is right too
        assert "was NOT built" in jpeg and "libjpeg" in jpeg
    elif works:
        assert jpeg.startswith("hpe: built the region JPEG decoder _hpe_jpeg (")
        assert list((tmp_path / "lib").glob("_hpe_jpeg*"))
    else:
        assert "was NOT built" in jpeg and "libjpeg" in jpeg
        assert not list((tmp_path / "lib").glob("_hpe_jpeg*"))
    if works:  # a C compiler is all the kernels need
        assert kern.startswith("hpe: built the compiled column kernels _hpe_kernels (")
        assert list((tmp_path / "lib").glob("_hpe_kernels*"))
    else:
        assert "was NOT built" in kern and "numpy twins will run" in kern
        assert not list((tmp_path / "lib").glob("_hpe_kernels*"))
