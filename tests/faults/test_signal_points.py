"""A signal at any point of a run with two outputs (``hpe audit -o FILE --json FILE``): before the commit it
leaves nothing and exits 128+N with one line; after the commit the run is complete (both outputs, whole),
exits 0 and, if the signal came while hpe could still speak, says so. Never a mix, never a temp file.

The signal is sent when the run reaches a point seen from outside: its temp files appear, the first or both
targets appear, plus small delays; the points are many, the run is short (40,000 rows)."""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import hpe_popen

from .conftest import temp_files

N = 40_000


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    path = tmp_path_factory.mktemp("in") / "in.parquet"
    rng = np.random.default_rng(1)
    pq.write_table(pa.table({k: rng.uniform(-80, 80, N) for k in ("pitch", "yaw", "roll")}), path)
    return path


def _first_temp(names):
    return any(n.startswith(".hpe-") for n in names)


def _temps(names):
    return sum(n.startswith(".hpe-") for n in names) >= 2


def _one_target(names):
    return "a.csv" in names or "r.json" in names


def _both(names):
    return "a.csv" in names and "r.json" in names


POINTS = [(_first_temp, 0.0), (_temps, 0.0), (_one_target, 0.0), (_both, 0.0)]


@pytest.mark.parametrize(
    "sig,points", [(signal.SIGTERM, POINTS), (signal.SIGINT, POINTS[:1] + POINTS[-1:])], ids=["SIGTERM", "SIGINT"]
)
def test_signal_at_many_points_of_audit(tmp_path, table, sig, points):
    outcomes = []
    for k, (trigger, delay) in enumerate(points):
        d = tmp_path / f"run{k}"
        d.mkdir()
        proc = hpe_popen("audit", table, "-o", d / "a.csv", "--json", d / "r.json")
        sent = False
        while proc.poll() is None:
            if trigger(os.listdir(d)):
                time.sleep(delay)
                proc.send_signal(sig)
                sent = True
                break
        _, err = proc.communicate(timeout=60)
        err = err.decode()
        names = sorted(os.listdir(d))
        assert not temp_files(d), (k, names)
        assert "Traceback" not in err, err
        if proc.returncode == 128 + sig:
            assert names == [], (k, names, err)
            assert err.strip().splitlines() == [f"Error: interrupted ({signal.Signals(sig).name})"], err
            outcomes.append("nothing")
        else:
            assert proc.returncode == 0, (k, proc.returncode, err)
            assert names == ["a.csv", "r.json"], (k, names, err)
            assert json.loads((d / "r.json").read_text())["rows"] == N
            with open(d / "a.csv") as fh:
                assert sum(1 for _ in fh) == N + 1
            assert "Error" not in err, err
            if sent and "received after the outputs were committed" in err:
                assert err.count("the run is complete") == 1
            outcomes.append("complete")
    assert "nothing" in outcomes, outcomes  # the early points do interrupt the run
