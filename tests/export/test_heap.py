"""glibc's malloc thresholds, raised once per process by the row jobs (export's workers, convert, audit)."""

import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")

CODE = """
import os, sys
from hpe_cli.pipelines.heap import keep_freed_memory, raise_malloc_thresholds
print(keep_freed_memory(), raise_malloc_thresholds(1 << 20, 2 << 20), raise_malloc_thresholds(1 << 20, 2 << 20))
"""


def _run(env_extra):
    import os

    env = {**os.environ, **env_extra}
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, env=env, check=True)
    return out.stdout.split()


def test_thresholds_are_raised_once_and_the_users_setting_wins():
    assert _run({}) == ["False", "True", "False"]  # no command running: left alone; set once
    assert _run({"MALLOC_TRIM_THRESHOLD_": "65536"})[0] == "False"


def test_export_workers_restore_frame_sized_malloc_under_dask_setting():
    import hpe_cli.pipelines.export.workers as w
    from hpe_cli.pipelines import heap

    calls = []
    real = heap.raise_malloc_thresholds
    try:
        w.raise_malloc_thresholds = lambda *a: calls.append(a) or True
        import os

        old = os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        w._frame_sized_malloc()
        os.environ["MALLOC_TRIM_THRESHOLD_"] = "65536"
        w._frame_sized_malloc()
    finally:
        w.raise_malloc_thresholds = real
        if old is None:
            os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        else:
            os.environ["MALLOC_TRIM_THRESHOLD_"] = old
    assert calls == [(128 << 20, 256 << 20)]
