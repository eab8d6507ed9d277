"""Output faults for every command: collisions, links, OS errors, long and non-UTF-8 names, modes.

Each case asserts exit code, one error line naming the user's file (never a temp file), no traceback,
nothing written (no partial output, no temp files) and inputs unchanged.
"""

from __future__ import annotations

import errno
import os
import stat

import pytest

from conftest import hpe

from .conftest import COMMANDS, check_failed, temp_files, tree


def _valid(case):
    res = hpe(*case.args())
    assert res.exit_code == 0, res.output
    return res


@pytest.mark.parametrize("cmd", COMMANDS)
def test_valid_run_writes_every_output_with_the_umask_mode(case_factory, cmd):
    case = case_factory(cmd)
    before = {str(p): p.read_bytes() for p in case.inputs}
    old = os.umask(0o027)
    try:
        _valid(case)
    finally:
        os.umask(old)
    for opt, p in case.outputs.items():
        if opt == "--rejects" and not p.exists():
            continue  # no rows rejected
        assert p.exists(), opt
        if p.is_file():
            assert stat.S_IMODE(p.stat().st_mode) == 0o640, p
    assert not temp_files(case.tmp)
    assert {str(p): p.read_bytes() for p in case.inputs} == before


def test_audit_plots_are_part_of_the_run(case_factory):
    """--plots files are staged with the run: a failing later output leaves no plot and no folder."""
    case = case_factory("audit")
    plots = case.tmp / "plots"
    blocker = case.tmp / "blocker"
    blocker.write_text("x")
    snap = tree(case.tmp)
    check_failed(hpe(*case.args(**{"--json": blocker / "r.json"}), "--plots", plots), blocker)
    assert tree(case.tmp) == snap
    line = check_failed(hpe(*case.args(), "--plots", case.inputs[0], "--overwrite"), case.inputs[0], codes=(1, 2))
    assert tree(case.tmp) == snap, line
    res = hpe(*case.args(), "--plots", plots)
    assert res.exit_code == 0 and (plots / "index.html").exists() and not temp_files(case.tmp), res.output


def _refused(case, outputs, names, overwrite=True):
    snap = tree(case.tmp)
    args = case.args(**outputs) + (["--overwrite"] if overwrite else [])
    line = check_failed(hpe(*args))
    for n in names:
        assert str(n) in line, line
    assert "must differ" in line
    assert tree(case.tmp) == snap  # nothing written, nothing removed, inputs unchanged
    return line


@pytest.mark.parametrize("cmd", COMMANDS)
def test_two_outputs_on_one_file(case_factory, cmd):
    case = case_factory(cmd)
    opts = [o for o, p in case.outputs.items() if p.suffix]  # file outputs
    if len(opts) < 2:
        pytest.skip("one file output")
    a, b = opts[:2]
    shared = case.outputs[a]
    _refused(case, {b: shared}, [shared])


@pytest.mark.parametrize("cmd", COMMANDS)
@pytest.mark.parametrize("how", ["same", "symlink", "hardlink", "symlinked_folder"])
def test_output_is_an_input(case_factory, cmd, how, tmp_path):
    case = case_factory(cmd)
    inp = case.inputs[0]
    opt = case.file_option
    if how == "same":
        target = inp
    elif how == "symlink":
        target = tmp_path / ("link" + inp.suffix)
        target.symlink_to(inp)
    elif how == "hardlink":
        target = tmp_path / ("hard" + inp.suffix)
        os.link(inp, target)
    else:
        (tmp_path / "alias").symlink_to(inp.parent)
        target = tmp_path / "alias" / inp.name
    _refused(case, {opt: target}, [target, inp])


@pytest.mark.parametrize("cmd", COMMANDS)
def test_existing_output_kept_without_overwrite_and_mode_kept_with_it(case_factory, cmd):
    case = case_factory(cmd)
    out = case.outputs[case.file_option] if cmd != "draw" else case.outputs["-o"] / "a.png"
    out.parent.mkdir(exist_ok=True)
    out.write_bytes(b"precious")
    os.chmod(out, 0o600)
    snap = tree(case.tmp)
    check_failed(hpe(*case.args()), out)
    assert tree(case.tmp) == snap
    res = hpe(*case.args(), "--overwrite")
    assert res.exit_code == 0, res.output
    assert out.read_bytes() != b"precious"
    assert stat.S_IMODE(out.stat().st_mode) == 0o600
    assert not temp_files(case.tmp)


@pytest.mark.parametrize("cmd", COMMANDS)
@pytest.mark.parametrize("code", [errno.EACCES, errno.EROFS, errno.ENOSPC])
def test_os_error_creating_an_output_names_it(case_factory, cmd, code, monkeypatch):
    """The OS refuses every new file in the output folder (a simulated unwritable / read-only / full disk)."""
    case = case_factory(cmd)
    folder = case.tmp / "out"
    folder.mkdir()
    outs = {o: folder / p.name for o, p in case.outputs.items()}
    snap = tree(case.tmp)
    real_open, real_mkdir = os.open, os.mkdir

    def refusing_open(path, flags, *a, **k):
        if os.path.dirname(os.path.abspath(path)).startswith(str(folder)) and flags & os.O_CREAT:
            raise OSError(code, os.strerror(code), path)
        return real_open(path, flags, *a, **k)

    def refusing_mkdir(path, *a, **k):
        if os.path.abspath(path).startswith(str(folder)):
            raise OSError(code, os.strerror(code), path)
        return real_mkdir(path, *a, **k)

    monkeypatch.setattr(os, "open", refusing_open)
    monkeypatch.setattr(os, "mkdir", refusing_mkdir)
    res = hpe(*case.args(**outs))
    monkeypatch.undo()
    line = check_failed(res)
    assert str(folder) in line
    reason = {errno.EACCES: "permission denied", errno.EROFS: "read-only file system", errno.ENOSPC: "disk full"}[code]
    assert reason in line, line
    assert tree(case.tmp) == snap


@pytest.mark.parametrize("cmd", ["convert", "relabel-panoptic", "relabel-agora", "audit", "augment"])
def test_disk_full_while_writing_a_table(case_factory, cmd, monkeypatch):
    """ENOSPC from Arrow's writer mid-write: the error names the output, nothing is left."""
    import pyarrow.csv as pcsv

    case = case_factory(cmd)
    snap = tree(case.tmp)
    real = pcsv.CSVWriter

    class FullDisk:
        def __init__(self, *a, **k):
            self._w = real(*a, **k)

        def write(self, *a, **k):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            self._w.close()

    monkeypatch.setattr(pcsv, "CSVWriter", FullDisk)
    res = hpe(*case.args())
    monkeypatch.undo()
    line = check_failed(res)
    assert "disk full" in line and any(str(p) in line for p in case.outputs.values()), line
    assert tree(case.tmp) == snap


@pytest.mark.parametrize("cmd", COMMANDS)
def test_name_too_long_is_named_and_a_long_legal_name_works(case_factory, cmd):
    case = case_factory(cmd)
    opt = case.file_option
    suffix = case.outputs[opt].suffix
    long_ok = case.tmp / ("a" * (255 - len(suffix)) + suffix)  # the longest legal name
    res = hpe(*case.args(**{opt: long_ok}))
    assert res.exit_code == 0, res.output
    assert long_ok.exists() and not temp_files(case.tmp)
    too_long = case.tmp / ("b" * 300 + suffix)
    snap = tree(case.tmp)
    line = check_failed(hpe(*case.args(**{opt: too_long}), "--overwrite"))
    assert "name too long" in line and "b" * 300 in line
    assert tree(case.tmp) == snap


@pytest.mark.parametrize("cmd", COMMANDS)
def test_non_utf8_output_names(case_factory, cmd):
    case = case_factory(cmd)
    folder = case.tmp / os.fsdecode(b"caf\xe9")
    folder.mkdir()
    outs = {o: folder / p.name for o, p in case.outputs.items()}
    res = hpe(*case.args(**outs))
    assert res.exit_code == 0, res.output
    assert "caf\\xe9" in res.output or not res.output.strip() or "caf" in res.output
    assert not temp_files(case.tmp)
    assert any(p.exists() for p in outs.values())


def test_non_utf8_input_name_is_one_line(tmp_path, case_factory):
    case = case_factory("convert")
    src = tmp_path / os.fsdecode(b"\xff.csv")
    src.write_bytes(case.inputs[0].read_bytes())
    res = hpe("convert", src, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "6drepnet")
    if res.exit_code != 0:
        line = check_failed(res)
        assert "\\xff.csv" in line
    assert not temp_files(tmp_path)


@pytest.mark.parametrize("cmd", COMMANDS)
def test_output_where_a_folder_or_file_is(case_factory, cmd):
    case = case_factory(cmd)
    opt = case.file_option
    case.outputs[opt].mkdir()
    snap = tree(case.tmp)
    check_failed(hpe(*case.args(), "--overwrite"), case.outputs[opt], codes=(1, 2))
    assert tree(case.tmp) == snap
    blocker = case.tmp / "blocker"
    blocker.write_text("x")
    snap = tree(case.tmp)
    check_failed(hpe(*case.args(**{opt: blocker / ("x" + case.outputs[opt].suffix)})), blocker, codes=(1, 2))
    assert tree(case.tmp) == snap


@pytest.mark.parametrize("cmd", ["convert", "draw", "audit"])
def test_failure_after_the_first_output_leaves_nothing(case_factory, cmd):
    """A later output fails (its folder is a file): the outputs staged before it are not committed."""
    case = case_factory(cmd)
    blocker = case.tmp / "blocker"
    blocker.write_text("x")
    last = list(case.outputs)[-1]
    bad = blocker / case.outputs[last].name
    snap = tree(case.tmp)
    check_failed(hpe(*case.args(**{last: bad})), blocker, codes=(1, 2))
    assert tree(case.tmp) == snap
