"""Every early-error path of every command ends with exit 1 or 2 -- never an abort -- under CPU load.

Runs the cases of ``benchmarks/early_errors.py`` (missing column, existing
output without --overwrite, unknown system, missing file; convert, audit, draw,
augment, evaluate, export, relabel-panoptic) at least 50 times in fresh
``python -m hpe_cli`` processes while another process burns a core. Before the
clean exit, ~1 run in 5 of the convert case ended in ``terminate called without
an active exception`` (exit 134).
"""

from __future__ import annotations

from conftest import repo_module


def _bench():
    return repo_module("benchmarks/early_errors.py")


def test_every_early_error_exits_1_or_2_under_load(tmp_path):
    """Usage errors (unknown system, missing file) exit 2, bad input 1; one 'Error:' line; no abort, no traceback."""
    bench = _bench()
    n_cases = len(bench.cases(bench.make_inputs(tmp_path / "probe")))
    n = max(50, 3 * n_cases)
    counts = bench.run(n, 4, tmp_path / "runs")
    unexpected = counts.pop("unexpected")
    assert sum(counts.values()) == n >= 50
    assert set(counts) <= {1, 2}, dict(counts)  # 134 = abort, 120 = flush failure, -N = signal
    assert unexpected == 0
