"""``hpe infer --callable/--decoder`` runs the user's code in a child process: whatever the code does
(hang, sys.exit, os._exit, crash, exception), hpe answers with one error line and exit 1, writes
nothing, and leaves no process behind."""

from __future__ import annotations

import multiprocessing
import textwrap

import pytest

from conftest import hpe

from .conftest import check_failed, temp_files, tree

BODIES = {
    "hang": ("def f(p, y, r):\n    while True:\n        pass\n", "no answer within --timeout"),
    "exit0": ("import sys\ndef f(p, y, r):\n    sys.exit(0)\n", "sys.exit(0)"),
    "os_exit": ("import os\ndef f(p, y, r):\n    os._exit(0)\n", "exit status 0"),
    "crash": ("import os, signal\ndef f(p, y, r):\n    os.kill(os.getpid(), signal.SIGSEGV)\n", "crashed (SIGSEGV)"),
    "raises": ("def f(p, y, r):\n    raise ValueError('nope')\n", "ValueError"),
    "import_exit": ("import sys\nsys.exit(0)\ndef f(p, y, r):\n    pass\n", "sys.exit(0)"),
}


@pytest.mark.parametrize("kind", list(BODIES))
@pytest.mark.parametrize("mode", ["--callable", "--decoder"])
def test_user_code_cannot_escape(tmp_path, kind, mode):
    if mode == "--decoder" and kind != "hang":
        pytest.skip("one decoder case per class is enough")
    body, expected = BODIES[kind]
    code = tmp_path / "user.py"
    code.write_text(textwrap.dedent(body).replace("(p, y, r)", "(R)" if mode == "--decoder" else "(p, y, r)"))
    snap = tree(tmp_path)
    res = hpe("infer", mode, f"{code}:f", "--timeout", "1", "-o", tmp_path / "s.toml", "--json", tmp_path / "r.json")
    line = check_failed(res, str(code))
    assert expected in line, line
    assert tree(tmp_path) == snap and not temp_files(tmp_path)
    assert not [p for p in multiprocessing.active_children() if p.name == "hpe-infer-user-code"]


def test_output_can_never_be_the_users_code(tmp_path):
    code = tmp_path / "user.toml.py"
    code.write_text("def f(p, y, r):\n    return [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n")
    before = code.read_bytes()
    res = hpe("infer", "--callable", f"{code}:f", "--json", code, "--overwrite")
    line = check_failed(res, str(code))
    assert "must differ" in line
    assert code.read_bytes() == before
