"""``--threads N`` on evaluate, convert, audit and augment: the outputs are the same bytes whatever the number.

Tables of several batches (``--batch-size``) so that chunks are really processed side by side, with
predictions in GT order (streamed) and shuffled (key join), every protocol.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import hpe
from hpe_cli.cli.main import cli
from hpe_cli.cli.options import THREADS_HELP


def _tables(tmp_path, n=9000, shuffled=False):
    rng = np.random.default_rng(7)
    g = np.c_[rng.uniform(-99, 99, n), rng.uniform(-99, 99, n), rng.uniform(-99, 99, n)]
    g[:50, 1] = 90.0  # gimbal lock rows
    p = g + rng.normal(0, 5, (n, 3))
    names = np.array([f"img{k}" for k in range(n)], dtype=object)
    pq.write_table(
        pa.table({"image": names, "pitch": g[:, 0], "yaw": g[:, 1], "roll": g[:, 2]}), tmp_path / "gt.parquet"
    )
    order = rng.permutation(n) if shuffled else np.arange(n)
    pred = pa.table({"image": names[order], "pitch": p[order, 0], "yaw": p[order, 1], "roll": p[order, 2]})
    pq.write_table(pred, tmp_path / "pred.parquet")
    return tmp_path / "gt.parquet", tmp_path / "pred.parquet"


@pytest.mark.parametrize("shuffled", [False, True])
def test_evaluate_same_bytes_for_1_and_2_threads(tmp_path, shuffled):
    gt, pred = _tables(tmp_path, shuffled=shuffled)
    out = {}
    for t in (1, 2, 3):
        d = tmp_path / f"t{t}"
        d.mkdir()
        hpe(
            "evaluate", pred, gt, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "--batch-size", "1000",
            "--json", d / "r.json", "-o", d / "rows.parquet", "--yaw-bins", "30", "--threads", t, "-q",
            ok=True,
        )  # fmt: skip
        rep = json.loads((d / "r.json").read_text())
        assert rep["n"]["pairs"] == 9000
        out[t] = ((d / "r.json").read_bytes(), pq.read_table(d / "rows.parquet"))
    for t in (2, 3):
        assert out[t][0] == out[1][0]
        assert out[t][1].equals(out[1][1])


def test_convert_and_audit_same_bytes_for_1_and_2_threads(tmp_path):
    gt, _ = _tables(tmp_path, n=5000)
    outs = {}
    for t in (1, 2):
        hpe("convert", gt, "-o", tmp_path / f"c{t}.parquet", "--from", "300w_lp", "--to", "6drepnet",
             "--batch-size", "700", "--threads", t, "-q", ok=True)  # fmt: skip
        hpe("audit", gt, "--system", "300w_lp", "--json", tmp_path / f"a{t}.json", "-o", tmp_path / f"a{t}.parquet",
             "--batch-size", "700", "--threads", t, "-q", ok=True)  # fmt: skip
        outs[t] = [pq.read_table(tmp_path / f"{k}{t}.parquet") for k in "ca"]
        outs[t].append(json.loads((tmp_path / f"a{t}.json").read_text()))
    assert outs[1][0].equals(outs[2][0])
    assert outs[1][1].equals(outs[2][1])
    assert outs[1][2] == outs[2][2]


@pytest.mark.parametrize("name", ["evaluate", "convert", "audit", "augment"])
def test_threads_help_says_the_default(name):
    r = hpe(name, "--help")
    assert "--threads N" in r.output
    assert "one per core" in r.output and "os.cpu_count()" in r.output
    opt = next(p for p in cli.get_command(None, name).params if "--threads" in p.opts)
    assert opt.help == THREADS_HELP


def test_threads_must_be_positive(tmp_path):
    gt, pred = _tables(tmp_path, n=10)
    r = hpe("convert", gt, "-o", tmp_path / "c.parquet", "--from", "300w_lp", "--to", "6drepnet", "--threads", "0")  # fmt: skip
    assert r.exit_code == 2 and "--threads" in r.output


def test_augment_same_bytes_for_1_and_2_threads(tmp_path):
    """augment's batch pool (``--threads``): labels, landmarks and boxes moved the same whatever the number."""
    gt, _ = _tables(tmp_path, n=5000)
    for t in (1, 2, 3):
        hpe("augment", gt, "-o", tmp_path / f"g{t}.parquet", "--image-size", "450x450", "--hflip",
             "--batch-size", "700", "--threads", t, "-q", ok=True)  # fmt: skip
    first = pq.read_table(tmp_path / "g1.parquet")
    assert first.num_rows == 5000
    for t in (2, 3):
        assert pq.read_table(tmp_path / f"g{t}.parquet").equals(first)
