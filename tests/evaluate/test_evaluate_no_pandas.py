"""``hpe evaluate`` with files in different orders (the partitioned key join) never imports pandas.

pandas costs 0.3 s and 35 MB a process (``pa.array``, ``pa.table``, ``Array.to_numpy`` and
``Schema.empty_table`` load it); the evaluation builds its Arrow data from numpy buffers instead.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import hpe_cli

ROOT = Path(hpe_cli.__file__).resolve().parents[1]  # the hpe_cli this test session imports

CHILD = """
import sys
from hpe_cli.cli.main import cli
cli.main(sys.argv[1:], standalone_mode=False)
print("PANDAS", "pandas" in sys.modules)
"""


def test_shuffled_evaluate_does_not_import_pandas(tmp_path):
    rng = np.random.default_rng(3)
    n = 3000
    g = rng.uniform(-80, 80, (n, 3))
    names = np.array([f"img{k}" for k in range(n)], dtype=object)
    pq.write_table(
        pa.table({"image": names, "pitch": g[:, 0], "yaw": g[:, 1], "roll": g[:, 2]}), tmp_path / "g.parquet"
    )
    o = rng.permutation(n)
    p = g[o] + rng.normal(0, 3, (n, 3))
    pq.write_table(
        pa.table({"image": names[o], "pitch": p[:, 0], "yaw": p[:, 1], "roll": p[:, 2]}), tmp_path / "p.parquet"
    )
    args = ["evaluate", tmp_path / "p.parquet", tmp_path / "g.parquet", "--pred-system", "300w_lp"]
    args += ["--gt-system", "300w_lp", "--protocol", "hopenet", "--json", tmp_path / "r.json", "-q"]
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, "-c", CHILD, *map(str, args)], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert "PANDAS False" in r.stdout, r.stdout
    assert json.loads((tmp_path / "r.json").read_text())["n"]["pairs"] == n
