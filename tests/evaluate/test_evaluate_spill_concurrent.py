"""The key join's partition files written for both sides at once (``spill.Partitions.fill``): the same report and
per-row bytes as one side after the other (``--threads 1``) and as the in-memory join, stems on both sides of a
two-column key (their hashes computed again from the keys), and the ground truth's error first when both fail."""

import os

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from hpe_cli.errors import HpeError
from hpe_cli.pipelines.evaluate import EvaluateOptions, run_evaluate
from hpe_cli.pipelines.evaluate import spill as es
from hpe_cli.rotation.systems import get_system

S = get_system("300w_lp")


@pytest.fixture
def two_key_files(tmp_path):
    rng = np.random.default_rng(11)
    n = 2500
    names = [f"{d}/im{i:05d}.png" for i, d in zip(range(n), rng.choice(["a", "b\\c"], n))]
    gt = pd.DataFrame(
        {
            "image": names,
            "person": rng.integers(0, 3, n),
            "pitch": rng.uniform(-60, 60, n),
            "yaw": rng.uniform(-80, 80, n),
            "roll": rng.uniform(-60, 60, n),
        }
    )
    pred = gt.sample(frac=1.0, random_state=2).iloc[:-30].copy()
    pred["image"] = [f"other/{s.split('/')[-1].split(chr(92))[-1].replace('.png', '.jpg')}" for s in pred["image"]]
    pred["yaw"] += rng.normal(0, 2, len(pred))
    gt.to_csv(tmp_path / "gt.csv", index=False)
    pred.to_csv(tmp_path / "pred.csv", index=False)
    return tmp_path


def _run(folder, tag, **kw):
    o, j, rej = folder / f"{tag}.parquet", folder / f"{tag}.json", folder / f"{tag}_rejects.csv"
    options = EvaluateOptions(
        pred_system=S,
        gt_system=S,
        keys=("image", "person"),
        output=o,
        report=j,
        rejects=rej,
        batch_size=211,
        partition_rows=300,
        overwrite=True,
        **kw,
    )
    rep = run_evaluate(folder / "pred.csv", folder / "gt.csv", options)
    return rep, o.read_bytes(), j.read_text(), rej.read_bytes()


def test_both_sides_at_once_same_bytes_as_one_after_the_other(two_key_files):
    rep2, rows2, json2, rej2 = _run(two_key_files, "t2", threads=2)
    rep1, rows1, json1, rej1 = _run(two_key_files, "t1", threads=1)
    assert (rows1, json1, rej1) == (rows2, json2, rej2)
    assert rep2["n"]["pairs"] == 2470 and rep2["n"]["missing"] == 30
    assert any("'image' joined on file stems" in n for n in rep2["notes"])
    mem, _, _, _ = _run(two_key_files, "mem", threads=2, join_engine="memory")
    assert (mem["n"], mem["notes"]) == (rep2["n"], rep2["notes"])
    flat = [pd.json_normalize(r["metrics"]).iloc[0] for r in (mem, rep2)]  # summed in another order: rounding
    assert np.allclose(flat[0].astype(float), flat[1].astype(float), rtol=1e-12, atol=1e-12)
    # the pairs themselves, against a dict of the keys' stems
    got = pq.read_table(two_key_files / "t2.parquet").to_pandas()
    gt = pd.read_csv(two_key_files / "gt.csv")
    stem = {(s.replace("\\", "/").split("/")[-1][:-4], p): y for s, p, y in zip(gt["image"], gt["person"], gt["yaw"])}
    assert len(got) == 2470
    keyed = [(s.replace("\\", "/").split("/")[-1][:-4], p) for s, p in zip(got["image"], got["person"])]
    assert np.allclose([stem[k] for k in keyed], got["gt_yaw"], atol=1e-9)


@pytest.mark.parametrize("failing", [("gt", "pred"), ("pred",), ("gt",)])
def test_the_ground_truths_error_first_and_no_temp_files(two_key_files, monkeypatch, failing):
    add = es._SideSpill.add
    folders = []

    def failing_add(self, c, keys):
        folders.append(self.folder)
        if self.name in failing:
            raise HpeError(f"{self.name} failed")
        return add(self, c, keys)

    monkeypatch.setattr(es._SideSpill, "add", failing_add)
    with pytest.raises(HpeError, match=f"^{failing[0]} failed$"):
        _run(two_key_files, "x", threads=2)
    assert folders and not any(os.path.exists(f) for f in folders)


@pytest.mark.parametrize("dictionary", [False, True])
def test_grouped_chunks_hold_the_rows_of_the_batches(tmp_path, dictionary):
    """The spill's reader puts consecutive batches together (``SideReader.group_rows``): the same rows, lines, keys
    and angles in the same order as batch by batch; batches with dictionary columns are kept as read."""
    import pyarrow as pa

    from hpe_cli.io import open_table
    from hpe_cli.pipelines.evaluate.sides import SideReader, open_side

    n = 1000
    rng = np.random.default_rng(4)
    keys = pa.array([f"k{i}" for i in range(n)])
    t = pa.table(
        {
            "image": keys.dictionary_encode() if dictionary else keys,
            "pitch": rng.uniform(-50, 50, n),
            "yaw": rng.uniform(-50, 50, n),
            "roll": rng.uniform(-50, 50, n),
        }
    )
    pq.write_table(t, tmp_path / "t.parquet", row_group_size=170)

    def read(group_rows):
        r = SideReader(open_side(open_table(tmp_path / "t.parquet", 64, with_lines=True), S, "auto", "gt"), ["image"],
                       None, False)  # fmt: skip
        r.group_rows = group_rows
        chunks = list(r.chunks())
        keys = [k for c in chunks for k in c.keys.column("image").to_pylist()]
        return len(chunks), keys, np.concatenate([c.lines for c in chunks]), np.concatenate([c.raw for c in chunks])

    n1, k1, l1, r1 = read(0)
    n2, k2, l2, r2 = read(300)
    assert k1 == k2 == [f"k{i}" for i in range(n)] and (l1 == l2).all() and (r1 == r2).all()
    assert n1 > n2 if not dictionary else n1 == n2
