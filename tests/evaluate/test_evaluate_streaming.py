"""Streamed scoring (chunks, sums, float32 spill) equals the whole-array computation, on the golden syn set."""

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.metrics.evaluate import compute_rows, evaluate_canonical, yaw_bin_edges
from hpe_cli.metrics.protocols import PROTOCOLS
from hpe_cli.metrics.stream import Accumulator
from hpe_cli.rotation.systems import get_system

SYN = Path(__file__).resolve().parents[3] / "shared" / "golden" / "evaluate" / "syn"
pytestmark = pytest.mark.skipif(not SYN.is_dir(), reason="shared/golden/evaluate not available")
A = ["pitch", "yaw", "roll"]


def _close(a, b, path=""):
    if isinstance(a, dict):
        assert set(a) == set(b), (path, set(a) ^ set(b))
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        if "median" in path or "p90" in path or "p95" in path:  # float32 spill: exact up to float32 rounding
            assert abs(a - b) <= 1e-5 * max(1.0, abs(b)), (path, a, b)
        else:
            assert (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-9 * max(1.0, abs(b)), (path, a, b)
    else:
        assert a == b, (path, a, b)


def test_accumulator_in_chunks_equals_whole_arrays():
    s = get_system("300w_lp")
    gt, pr = pd.read_csv(SYN / "gt.csv"), pd.read_csv(SYN / "pred.csv")
    G = [[np.asarray(x, float) for x in r] for r in s.soa_to_canonical(s.soa_from_angles(*gt[A].to_numpy().T))]
    P = [[np.asarray(x, float) for x in r] for r in s.soa_to_canonical(s.soa_from_angles(*pr[A].to_numpy().T))]
    raw = {"gt": (s, gt[A].to_numpy()), "pred": (s, pr[A].to_numpy())}
    by = np.where(np.arange(len(gt)) % 3 == 0, "a", "b")
    part, _ = evaluate_canonical(P, G, gt_system=s, by=by, yaw_bins=30, raw=raw)
    names = [n for n in PROTOCOLS if n != "opal23-align"]  # global: its mean comes from all chunks (pipeline)
    acc = Accumulator({k: PROTOCOLS[k] for k in names}, yaw_edges=yaw_bin_edges(s, 30), by=True)
    with acc:
        for a in range(0, len(gt), 317):
            sl = slice(a, a + 317)
            rows = compute_rows(
                [[x[sl] for x in r] for r in P],
                [[x[sl] for x in r] for r in G],
                s,
                names,
                {k: (v[0], v[1][sl]) for k, v in raw.items()},
            )
            acc.add(rows, by[sl])
        rep = acc.report()
    protos = {k: v for k, v in part["protocols"].items() if k in names}
    _close(
        {"metrics": part["metrics"], "protocols": protos}, {"metrics": rep["metrics"], "protocols": rep["protocols"]}
    )
    for g in ("a", "b"):
        want = part["by"]["groups"][g]
        _close(
            {"metrics": want["metrics"], "n": want["n"]},
            {"metrics": rep["by_groups"][g]["metrics"], "n": rep["by_groups"][g]["n"]},
        )
    for w, h in zip(part["yaw_bins"], rep["yaw_bins"]):
        _close(w["metrics"], h["metrics"])


def _run(tmp_path, pred, *args):
    rep = tmp_path / f"{pred.stem}.json"
    r = hpe(
        "evaluate",
        pred,
        SYN / "gt.csv",
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "--json",
        rep,
        "-q",
        "--batch-size",
        "256",
        "--by",
        "group",
        "--yaw-bins",
        "45",
        *args,
    )
    assert r.exit_code == 0, r.output
    return json.loads(rep.read_text())


@pytest.mark.parametrize("align", ["none", "mean"])
def test_streamed_run_equals_in_memory_join(tmp_path, align):
    p = pd.read_csv(SYN / "pred.csv")
    p["group"] = np.where(np.arange(len(p)) % 4 == 0, "even", "odd")
    ordered, shuffled = tmp_path / "ordered.csv", tmp_path / "shuffled.csv"
    p.to_csv(ordered, index=False)
    p.sample(frac=1.0, random_state=5).to_csv(shuffled, index=False)
    a = _run(tmp_path, ordered, "--align", align)
    b = _run(tmp_path, shuffled, "--align", align)
    assert a["inputs"]["paired"] == "streamed in file order" and "partition(s) on disk" in b["inputs"]["paired"]
    for k in ("metrics", "protocols", "by", "yaw_bins", "align"):
        _close(a[k], b[k], k)
    if align == "none":  # the streamed opal23 alignment (mean over all chunks) equals opal23's own numbers
        golden = {g["protocol"]: g["numbers"] for g in json.loads((SYN / "golden.json").read_text())["golden"]}
        for k in ("pitch", "yaw", "roll", "mean", "geodesic"):
            assert abs(a["protocols"]["opal23-align"][k] - golden["opal23_align"][k]) <= 1e-6, k


@pytest.mark.parametrize("shuffled", [False, True])
def test_threads_and_piece_sizes_change_nothing(tmp_path, monkeypatch, shuffled):
    """2 scoring and 2 label threads give exactly the numbers and rows of 1; 100-row pieces those of whole batches
    up to the order of the sums."""
    import hpe_cli.pipelines.evaluate.score as ev
    import hpe_cli.pipelines.evaluate.sides as ej

    p = pd.read_csv(SYN / "pred.csv")
    p["group"] = np.where(np.arange(len(p)) % 4 == 0, "even", "odd")
    pred = tmp_path / "pred.csv"
    (p.sample(frac=1.0, random_state=3) if shuffled else p).to_csv(pred, index=False)
    out = {}
    for threads, rows in ((1, 100), (2, 100), (1, 10**9)):
        monkeypatch.setattr(ev, "SCORE_THREADS", threads)
        monkeypatch.setattr(ev, "SCORE_ROWS", rows)
        monkeypatch.setattr(ej, "LABEL_THREADS", threads)
        rows_file = tmp_path / f"rows{threads}_{rows}.parquet"
        rep = _run(tmp_path, pred, "-o", str(rows_file), "--overwrite")
        out[threads, rows] = (rep, pd.read_parquet(rows_file))
    (a, ra), (b, rb), (c, rc) = out[1, 100], out[2, 100], out[1, 10**9]
    for k in ("metrics", "protocols", "by", "yaw_bins", "n"):
        assert a[k] == b[k], k  # the same sums in the same order: equal, not close
        _close(c[k], b[k], k)
    pd.testing.assert_frame_equal(ra, rb)
    pd.testing.assert_frame_equal(rc, rb)


CLI_NO_GC = "import gc, sys; gc.disable(); sys.argv[0] = 'hpe'; from hpe_cli.cli.main import main; main()"


def test_no_reading_or_scoring_thread_outlives_a_run(tmp_path):
    """The streamed attempt abandoned for the key join (files in different orders) stops its label threads at
    once: ``hpe``'s exit joins live threads (30 s each), and a run once took 134 s where 14 s of work was done."""
    import os
    import subprocess
    import sys
    import time

    p = pd.read_csv(SYN / "pred.csv")
    shuffled = tmp_path / "shuffled.csv"
    p.sample(frac=1.0, random_state=5).to_csv(shuffled, index=False)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    args = ["--pred-system", "300w_lp", "--gt-system", "300w_lp", "--batch-size", "64", "-q"]
    for pred in (shuffled, SYN / "pred.csv"):
        t = time.perf_counter()
        r = subprocess.run(
            # no cyclic garbage collection: a thread kept only by a reference cycle stays (as in big runs)
            [sys.executable, "-c", CLI_NO_GC, "evaluate", str(pred), str(SYN / "gt.csv"), *args],
            capture_output=True,
            text=True,
            env=env,
            timeout=300,
        )
        took = time.perf_counter() - t
        assert r.returncode == 0, r.stderr
        assert took < 25, f"{pred.name}: {took:.0f} s (threads left waiting at exit?)"


@pytest.mark.parametrize("order", ["unsorted", "sorted-then-not"])
def test_a_key_repeated_in_another_chunk_is_named(tmp_path, order):
    """Both files in the same order, one key twice, 200 rows apart (another chunk): the run stops with the key and
    both lines, as the key join does, instead of scoring two ambiguous pairs."""
    gt = pd.read_csv(SYN / "gt.csv").head(400).copy()
    pr = pd.read_csv(SYN / "pred.csv").head(400).copy()
    if order == "unsorted":
        idx = np.random.default_rng(2).permutation(400)
        gt, pr = gt.iloc[idx].reset_index(drop=True), pr.iloc[idx].reset_index(drop=True)
    else:  # the first chunks sorted, the rest not
        tail = np.r_[np.arange(200), 200 + np.random.default_rng(2).permutation(200)]
        gt, pr = gt.iloc[tail].reset_index(drop=True), pr.iloc[tail].reset_index(drop=True)
    gt.loc[350, "image"] = pr.loc[350, "image"] = gt.loc[150, "image"]
    gt.to_csv(tmp_path / "gt.csv", index=False)
    pr.to_csv(tmp_path / "pred.csv", index=False)
    args = ["--pred-system", "300w_lp", "--gt-system", "300w_lp", "--batch-size", "64", "-q"]
    r = hpe("evaluate", tmp_path / "pred.csv", tmp_path / "gt.csv", *args)
    assert r.exit_code == 1, r.output
    key = gt.loc[150, "image"]
    assert f"duplicate key image={key!r}" in r.output and "line 152" in r.output and "352" in r.output, r.output


def test_sorted_keys_are_streamed_without_hashing(tmp_path, monkeypatch):
    import hpe_cli.pipelines.evaluate.lockstep as ls

    spilled, hashed = [], []
    monkeypatch.setattr(ls.KeysSeen, "_spill", lambda self, g: spilled.append(g.n))
    real = ls.sorted_hashes
    monkeypatch.setattr(ls, "sorted_hashes", lambda t, keys: hashed.append(t.num_rows) or real(t, keys))
    p = pd.read_csv(SYN / "pred.csv")
    p["group"] = "all"
    pred = tmp_path / "pred.csv"
    p.to_csv(pred, index=False)
    assert (pd.read_csv(SYN / "gt.csv")["image"].is_monotonic_increasing) and p["image"].is_unique
    rep = _run(tmp_path, pred)
    assert rep["inputs"]["paired"] == "streamed in file order" and not spilled
    assert 1 <= len(hashed) <= 4 < len(p) // 256  # the first chunks, labelled before the pairing saw sorted keys


@pytest.mark.parametrize("shuffled", [False, True])
def test_opal23_align_scored_after_the_pass_equals_scored_inline(tmp_path, monkeypatch, shuffled):
    """opal23-align's chunks, spilled and scored once the Karcher mean is known, give exactly (equal, not close)
    the report of scoring every chunk inline with that mean known in advance (the former extra pass), with
    --by groups and yaw bins, on 1 and 2 threads."""
    import hpe_cli.pipelines.evaluate.opal23 as op
    import hpe_cli.pipelines.evaluate.run as run
    import hpe_cli.pipelines.evaluate.score as ev

    p = pd.read_csv(SYN / "pred.csv")
    p["group"] = np.where(np.arange(len(p)) % 4 == 0, "even", "odd")
    pred = tmp_path / "pred.csv"
    (p.sample(frac=1.0, random_state=3) if shuffled else p).to_csv(pred, index=False)
    means = []
    real_mean = op.KarcherSpill.mean
    monkeypatch.setattr(op.KarcherSpill, "mean", lambda self, **k: means.append(real_mean(self, **k)) or means[-1])
    monkeypatch.setattr(ev, "SCORE_ROWS", 100)
    later = _run(tmp_path, pred, "--protocol", "opal23-align", "--protocol", "opal23")
    assert len(means) == 1
    monkeypatch.setattr(ev, "deferred_protocols", lambda protocols, align: ())
    monkeypatch.setattr(run, "_globals", lambda *a: {"opal23_mean": means[0]})
    for threads in ("1", "2"):
        inline = _run(
            tmp_path, pred, "--protocol", "opal23-align", "--protocol", "opal23", "--threads", threads, "--overwrite"
        )
        for k in ("metrics", "protocols", "by_groups", "yaw_bins", "n"):
            assert later.get(k) == inline.get(k), k
    assert later["protocols"]["opal23-align"]["n"] == len(p)


@pytest.mark.parametrize("grouped", [False, True])
def test_streamed_percentiles_are_numpys_of_the_rows(tmp_path, monkeypatch, grouped):
    """The report's median, p90 and p95 (the first pass of the radix select counted on the scoring threads as the
    chunks stream, the second over the spill read back in two parts on two threads) are np.percentile's of the
    per-row geodesic errors as float32, to the bit: all pairs, and each --by group and yaw bin when asked."""
    import hpe_cli.metrics.stream as stream

    calls = []
    real = stream.percentiles_of_pieces
    monkeypatch.setattr(
        stream,
        "percentiles_of_pieces",
        lambda *a, **k: calls.append((len(a[0]), k["top"] is not None)) or real(*a, **k),
    )
    monkeypatch.setattr(stream, "SPILL_PIECE", 300)
    monkeypatch.setattr(stream.Accumulator, "threads", 2)
    p = pd.read_csv(SYN / "pred.csv")
    p["group"] = np.where(np.arange(len(p)) % 3 == 0, "a", "b")
    pred, rows, rep = tmp_path / "pred.csv", tmp_path / "rows.parquet", tmp_path / "rep.json"
    p.to_csv(pred, index=False)
    args = ["--pred-system", "300w_lp", "--gt-system", "300w_lp", "--batch-size", "256", "-q", "--protocol", "hopenet"]
    args += ["--by", "group", "--yaw-bins", "45"] if grouped else []
    r = hpe("evaluate", pred, SYN / "gt.csv", *args, "--json", rep, "-o", rows)
    assert r.exit_code == 0, r.output
    report, t = json.loads(rep.read_text()), pd.read_parquet(rows)
    assert calls == [(2, True)]  # the whole set: streamed first pass, two parts

    def check(block, geo):
        want = np.percentile(np.asarray(geo, dtype=np.float32), [50, 90, 95])
        got = [block["metrics"]["geodesic"][k] for k in ("median", "p90", "p95")]
        assert got == [float(x) for x in want]

    assert report["n"]["pairs"] == len(t) == len(p)
    check(report, t["geodesic"])
    if grouped:
        for g in ("a", "b"):
            check(report["by"]["groups"][g], t["geodesic"][p["group"].to_numpy() == g])
        yaw = t["gt_yaw"].to_numpy()
        for k, b in enumerate(report["yaw_bins"]):
            last = k == len(report["yaw_bins"]) - 1
            inside = (yaw >= b["lo"]) & ((yaw <= b["hi"]) if last else (yaw < b["hi"]))
            if inside.any():
                check(b, t["geodesic"][inside])
