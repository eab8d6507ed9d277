"""The cluster chain: ``relabel-panoptic --scheduler local`` -> ``export --scheduler local``, on the synthetic
multi-sequence release made from videos and on the real CMU Panoptic pizza1 sample (JPEG frames).

Oracle: the same chain in one process (``--workers 1``, no scheduler) gives the same bytes at both steps; the
exported ``annotation.txt`` lines each name a crop that exists (as ``test_chain_export_layouts.py`` reads them).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import hpe, repo_module

from .conftest import PIZZA

CAMS = "00_00,00_08,00_15,00_23"  # the pizza1 cameras with JPEGs in the sample

R = repo_module("tests/export/release.py")


def _chain(seq_root, tmp_path, monkeypatch, relabel_extra=(), dask: bool = False):
    """Both steps in their own folder, outputs named relative to it (export.json and the rejects name them)."""
    sched = ("--scheduler", "local", "--workers", "2") if dask else ()
    d = tmp_path / ("dask" if dask else "plain")
    d.mkdir()
    with monkeypatch.context() as m:
        m.chdir(d)
        res = hpe(
            "relabel-panoptic",
            seq_root,
            "-o",
            "labels.parquet",
            "--rejects",
            "rel_rej.csv",
            *relabel_extra,
            *sched,
            "-q",
        )
        assert res.exit_code == 0, res.output
        res = hpe(*R.export_args("whenet", "labels.parquet", seq_root, "whenet", "exp_rej.csv", *sched))
        assert res.exit_code == 0, res.output
    return d


def _whenet_reads(folder: Path) -> int:
    """``annotation.txt`` lines ``<image>,<yaw>,<pitch>,<roll>`` relative to the split folder (as
    ``test_chain_export_layouts.py::test_whenet_annotation_lines`` reads them)."""
    n = 0
    for line in (folder / "train" / "annotation.txt").read_text().splitlines():
        name, *angles = line.split(",")
        assert (folder / "train" / name).is_file() and len(angles) == 3
        n += 1
    return n


def _compare(a: Path, b: Path):
    for f in ("labels.parquet", "rel_rej.csv", "exp_rej.csv"):
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
    assert R.tree(a / "whenet") == R.tree(b / "whenet")


def test_chain_on_the_synthetic_release(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    root, _ = R.make_release(tmp_path / "in")
    plain, dask = _chain(root, tmp_path, monkeypatch), _chain(root, tmp_path, monkeypatch, dask=True)
    _compare(plain, dask)
    assert _whenet_reads(dask / "whenet") > 0


@pytest.mark.skipif(not PIZZA.exists(), reason="shared/realdata is not available")
def test_chain_on_the_real_pizza1_sample(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    extra = ("--cameras", CAMS)
    plain, dask = _chain(PIZZA, tmp_path, monkeypatch, extra), _chain(PIZZA, tmp_path, monkeypatch, extra, dask=True)
    _compare(plain, dask)
    assert _whenet_reads(dask / "whenet") > 0
