"""``hpe infer`` against hostile user code and hostile system files.

User code runs in its own process group: whatever it starts (a fork, ``sleep 3600``) is gone when
``hpe`` exits; a loop ends at ``--timeout``; closing its file descriptors gives one error line.
``--timeout`` takes positive finite seconds only. A system TOML with huge numbers, huge arrays or
deep nesting is one ``FILE: key: expected X, got Y`` line, quickly.
"""

from __future__ import annotations

import os
import textwrap
import time

import pytest

from conftest import hpe, hpe_process

GOOD = """
import math
from hpe_cli.rotation import get_system
S = get_system("300w_lp")
def good(p, y, r):
    return S.from_angles([[math.degrees(p), math.degrees(y), math.degrees(r)]])[0]
"""

CODES = {
    "popen_sleep": (
        """
import subprocess
STARTED = []
def f(p, y, r):
    if not STARTED:
        STARTED.append(subprocess.Popen(["sleep", "3600"]))
        open(PIDS, "a").write(f"{STARTED[0].pid}\\n")
    return good(p, y, r)
""",
        0,
    ),
    "fork": (
        """
import os, time
FORKED = []
def f(p, y, r):
    if not FORKED:
        pid = os.fork()
        if pid == 0:
            time.sleep(3600)
            os._exit(0)
        FORKED.append(pid)
        open(PIDS, "a").write(f"{pid}\\n")
    return good(p, y, r)
""",
        0,
    ),
    "spawn_then_loop": (
        """
import subprocess
def f(p, y, r):
    proc = subprocess.Popen(["sleep", "3600"])
    open(PIDS, "a").write(f"{proc.pid}\\n")
    while True:
        pass
""",
        1,
    ),
}


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


def _user(tmp_path, body):
    code = tmp_path / "user.py"
    pids = tmp_path / "pids.txt"
    code.write_text(f"PIDS = {str(pids)!r}\n" + textwrap.dedent(GOOD) + textwrap.dedent(body))
    return code, pids


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc")
@pytest.mark.parametrize("kind", list(CODES))
def test_nothing_the_code_starts_outlives_hpe(tmp_path, kind):
    body, status = CODES[kind]
    code, pids = _user(tmp_path, body)
    res = hpe_process("infer", "--callable", f"{code}:f", "--timeout", "3", "-o", tmp_path / "s.toml", text=False)
    err = res.stderr.decode()
    assert res.returncode == status, err
    assert "Traceback" not in err
    if status:
        assert len(err.strip().splitlines()) == 1 and "no answer within --timeout 3" in err
    else:
        assert "name = " in (tmp_path / "s.toml").read_text() or (tmp_path / "s.toml").stat().st_size > 0
    started = [int(p) for p in pids.read_text().split()]
    assert started
    deadline = time.monotonic() + 5
    while any(_alive(p) for p in started) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [p for p in started if _alive(p)], "processes started by the user code are still running"


@pytest.mark.parametrize("first", [3, 0])
def test_closing_file_descriptors_is_one_clean_line(tmp_path, first):
    code, _ = _user(
        tmp_path,
        f"""
import os
def f(p, y, r):
    os.closerange({first}, 4096)
    return good(p, y, r)
""",
    )
    res = hpe_process("infer", "--callable", f"{code}:f", "--timeout", "10", text=False)
    err = res.stderr.decode()
    assert res.returncode == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert str(code) in lines[0]


def test_code_that_writes_files_does_not_change_the_answer(tmp_path):
    out = tmp_path / "s.toml"
    code, _ = _user(
        tmp_path,
        f"""
def f(p, y, r):
    open({str(tmp_path / "junk.txt")!r}, "a").write("x")
    return good(p, y, r)
""",
    )
    res = hpe_process("infer", "--callable", f"{code}:f", "-o", out, text=False)
    assert res.returncode == 0, res.stderr.decode()
    assert (tmp_path / "junk.txt").exists() and "300w_lp" in res.stdout.decode() + out.read_text()


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "0", "-1", "1e309"])
def test_timeout_takes_positive_finite_seconds(tmp_path, value):
    res = hpe("infer", "--callable", f"{tmp_path / 'x.py'}:f", "--timeout", value)
    assert res.exit_code == 2, res.output
    assert "positive finite" in res.output and "Traceback" not in res.output


# ------------------------------------------------------------------------------------ hostile system files
TURNS = "".join(f'[[turns]]\nangle = "{a}"\naxis = "{x}"\n' for a, x in (("pitch", "x"), ("yaw", "y"), ("roll", "z")))
HOSTILE = {
    "int_5000_digits": (
        'name = "x"\nframe = [[1' + "0" * 5000 + ", 0, 0], [0, 1, 0], [0, 0, 1]]\n" + TURNS,
        "frame: expected a 64-bit integer (TOML), got a 5001-digit number",
    ),
    "int_400_digits": (
        'name = "x"\n' + TURNS + "[ranges]\npitch = [-1, 1" + "0" * 400 + "]\n",
        "ranges.pitch.1: expected a 64-bit integer (TOML), got a 401-digit number",
    ),
    "int_past_64_bits": (
        'name = "x"\ngimbal_tol = 99999999999999999999999\n' + TURNS,
        "gimbal_tol: expected a 64-bit integer (TOML), got a 23-digit number",
    ),
    "float_overflow": (
        'name = "x"\n' + TURNS + "[ranges]\npitch = [-1e400, 1e400]\n",
        "ranges.pitch: expected finite numbers, got [-Infinity, Infinity]",
    ),
    "huge_array": (
        'name = "x"\norder = [' + ",".join(['"pitch"'] * 100_000) + "]\n" + TURNS,
        "order: expected at most 256 items, got 100000",
    ),
    "huge_file": ('name = "' + "x" * 2_000_000 + '"\n' + TURNS, "file: expected a system file of at most"),
    "deep_array": (
        'name = "x"\nframe = ' + "[" * 50_000 + "]" * 50_000 + "\n" + TURNS,
        "frame: expected at most 6 levels of nesting",
    ),
    "deep_table": (
        'name = "x"\n' + TURNS + "[columns]\na = " + "{b = " * 3000 + "1" + "}" * 3000 + "\n",
        "columns.a: expected at most 6 levels of nesting",
    ),
    "nested_in_limits": (
        'name = "x"\n' + TURNS + "[columns]\na = [[[[[[[1]]]]]]]\n",
        "columns.a.0.0.0.0.0: expected at most 6 levels of nesting, got more",
    ),
}


@pytest.mark.parametrize("kind", list(HOSTILE))
def test_hostile_system_toml_is_one_line_quickly(tmp_path, kind):
    from hpe_cli.rotation.systems import SystemError_, load_system

    text, expected = HOSTILE[kind]
    path = tmp_path / f"{kind}.toml"
    path.write_text(text)
    t0 = time.monotonic()
    with pytest.raises(SystemError_) as info:
        load_system(path)
    assert time.monotonic() - t0 < 5
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and expected in msg and "\n" not in msg and len(msg) < 300, msg
    res = hpe("systems", path)  # the command line: one line, no traceback
    assert res.exit_code in (1, 2) and expected in res.output and "Traceback" not in res.output, res.output
    assert len([ln for ln in res.output.splitlines() if ln.strip()]) <= 3, res.output
