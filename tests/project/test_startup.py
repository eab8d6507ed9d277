"""What start-up loads: the heavy modules stay off the paths that do not need them (imports are at module level
elsewhere; the exceptions carry ``# lazy: REASON``, see test_house). Start-up times are in docs/performance.md."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("pandas", "cv2", "matplotlib", "scipy", "torch", "dask")


def _loaded(code: str) -> list:
    probe = f"{code}\nimport sys, json\nprint(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_help_loads_no_heavy_module_nor_pyarrow():
    code = (
        "from hpe_cli.cli.main import cli\n"
        "try:\n    cli.main(['--help'], standalone_mode=False)\nexcept SystemExit:\n    pass\n"
        "import sys\nassert 'pyarrow' not in sys.modules, 'pyarrow'\n"
    )
    assert _loaded(code) == []


@pytest.mark.parametrize("package", ["convert", "audit", "evaluate", "export"])
def test_table_pipelines_load_no_pandas_opencv_or_scipy(package):
    """convert, audit and evaluate read and write tables with pyarrow and numpy; export's images load OpenCV
    only when it cuts crops. The draw/plot/page code they call for --plots/--html loads lazily."""
    assert _loaded(f"import hpe_cli.pipelines.{package}") == []
