import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("hpe", max_examples=60, deadline=None)
settings.load_profile("hpe")

ROOT = Path(__file__).resolve().parents[1]
#: ``shared/realdata`` next to the checkout or next to a folder above it (worktrees live one level deeper)
REALDATA = next(
    (p / "shared" / "realdata" for p in ROOT.parents if (p / "shared" / "realdata").is_dir()),
    ROOT.parent / "shared" / "realdata",
)


def _arg(a):
    return a if isinstance(a, (str, bytes)) else str(a)


def _check(argv, got: int, ok: bool | None, code: int | None, output: str) -> None:
    """Fail with the command line and its output when the exit code ``got`` is not the one expected."""
    __tracebackhide__ = True
    want = 0 if ok is True else code
    bad = (want is not None and got != want) or (ok is False and got == 0)
    if bad:
        cmd = "hpe " + " ".join(os.fsdecode(a) for a in argv)
        expected = "a failure" if want is None else f"exit {want}"
        pytest.fail(f"{cmd}\nexpected {expected}, got exit {got}; output:\n{output}")


def hpe(*args, ok: bool | None = None, code: int | None = None, **kw):
    """``hpe ARGS`` run in this process by click's ``CliRunner`` (each argument ``str()``-ed, bytes kept).

    An exception that escapes the command (a traceback for a user) is raised, never folded into the exit
    code. ``ok=True`` asserts exit 0, ``ok=False`` a non-zero exit, ``code=N`` exit ``N``; a failed check shows
    the command line and its output. ``kw`` goes to ``CliRunner.invoke`` (``input=``, ``env=``,
    ``terminal_width=``...). Returns click's ``Result``: ``.exit_code``, ``.output`` (stdout and stderr
    interleaved), ``.stdout``, ``.stderr``.
    """
    from click.testing import CliRunner

    from hpe_cli.cli.main import cli

    __tracebackhide__ = True
    argv = [_arg(a) for a in args]
    res = CliRunner().invoke(cli, argv, catch_exceptions=False, **kw)
    _check(argv, res.exit_code, ok, code, res.output)
    return res


def hpe_env(**extra) -> dict:
    """The environment of an ``hpe`` child process: this worktree first on ``PYTHONPATH``, plus ``extra``."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "PYTHONPATH": path, **extra}


def hpe_process(*args, ok: bool | None = None, code: int | None = None, timeout=120, text=True, env=None, **kw):
    """``python -m hpe_cli ARGS`` in a separate process, waited for (what a user sees on the terminal).

    ``env`` adds variables to ``hpe_env()``. Returns the ``CompletedProcess`` (``.returncode``, ``.stdout``,
    ``.stderr``: ``str``, bytes with ``text=False``); ``ok``/``code`` as in ``hpe``. ``kw`` goes to
    ``subprocess.run`` (``input=``, ``cwd=``...).
    """
    __tracebackhide__ = True
    argv = [_arg(a) for a in args]
    proc = subprocess.run(
        [sys.executable, "-m", "hpe_cli", *argv],
        capture_output=True,
        text=text,
        env=hpe_env(**(env or {})),
        timeout=timeout,
        **kw,
    )
    _check(argv, proc.returncode, ok, code, f"{proc.stdout!s}\n{proc.stderr!s}")
    return proc


def hpe_popen(*args, env=None, **kw) -> subprocess.Popen:
    """``python -m hpe_cli ARGS`` started in a separate process and not waited for (signals, killed workers):
    stdout and stderr are pipes (bytes) unless ``kw`` says otherwise; ``env`` adds variables to ``hpe_env()``;
    ``kw`` goes to ``subprocess.Popen``."""
    kw = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, **kw}
    return subprocess.Popen([sys.executable, "-m", "hpe_cli", *map(_arg, args)], env=hpe_env(**(env or {})), **kw)


def repo_module(path: str):
    """A file of the repository that is not a package module (``benchmarks/``, ``scripts/``, ``tests/export/``),
    loaded as a module: ``repo_module("benchmarks/libm.py")``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(Path(path).stem, ROOT / path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def sample_data_script():
    """``scripts/make_sample_data.py`` as a module (synthetic Panoptic sequences, tars, videos, templates)."""
    return repo_module("scripts/make_sample_data.py")


@pytest.fixture
def realdata():
    if not REALDATA.exists():
        pytest.skip("../shared/realdata is not available")
    return REALDATA


def locate_dots(img, pts, r=7):
    """Sub-pixel intensity centroid of the dot nearest each expected position ``pts`` (N, 2) in a grey image
    (pixel centres at integers); a window of ``2 r + 1`` pixels around each."""
    out = []
    for x, y in pts:
        x0, y0 = int(round(x)), int(round(y))
        win = img[y0 - r : y0 + r + 1, x0 - r : x0 + r + 1].astype(float)
        gy, gx = np.mgrid[y0 - r : y0 + r + 1, x0 - r : x0 + r + 1]
        out.append([(win * gx).sum() / win.sum(), (win * gy).sum() / win.sum()])
    return np.array(out)


def canonical_A(pyr_deg):
    """SPEC §2's expanded 300W-LP matrix, written out independently of the package."""
    p, y, r = np.deg2rad(np.asarray(pyr_deg, dtype=float)).T
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    return np.stack(
        [
            np.stack([cy * cr, cy * sr, -sy], -1),
            np.stack([-cp * sr + sp * sy * cr, cp * cr + sp * sy * sr, sp * cy], -1),
            np.stack([sp * sr + cp * sy * cr, -sp * cr + cp * sy * sr, cp * cy], -1),
        ],
        -2,
    )
