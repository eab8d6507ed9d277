"""The built-in systems' files are read one by one on first use (``SystemTable``), and every caller sees what a
table filled at once gave: the same names in the same order, the same systems, the same messages."""

from __future__ import annotations

import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import hpe_cli.rotation.systems as systems_mod
from hpe_cli.rotation.systems import (
    SYSTEMS,
    SystemError_,
    SystemTable,
    builtin_systems,
    get_system,
    read_system_file,
    system_names,
)

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "systems"


def _table(folder: Path) -> SystemTable:
    """A fresh table of the ``*.toml`` files of ``folder`` (none read yet)."""
    table = SystemTable("built-in system")
    for entry in sorted(folder.glob("*.toml"), key=lambda p: p.name):
        table.register_file(entry)
    return table


@pytest.fixture
def counted(monkeypatch):
    read = []
    real = systems_mod.read_builtin_file

    def reading(entry):
        read.append(entry.name)
        return real(entry)

    monkeypatch.setattr(systems_mod, "read_builtin_file", reading)
    return read


def test_a_lookup_reads_that_file_only(counted):
    table = _table(CONFIGS)
    assert list(table) == sorted(p.stem for p in CONFIGS.glob("*.toml"))  # names without reading
    assert "opencv" in table and "nope" not in table and len(table) == len(list(CONFIGS.glob("*.toml")))
    assert counted == []
    s = table["opencv"]
    assert table.get("opencv") is s and table["opencv"] is s  # read once, one object
    assert counted == ["opencv.toml"]
    assert table.get("nope", None) is None
    with pytest.raises(ValueError, match="expected a built-in system among 300w_lp, 3ddfa_v2, .*, got 'nope'"):
        table.get("nope")


def test_listing_reads_them_all_and_gives_the_files_systems(counted):
    table = _table(CONFIGS)
    every = dict(table)
    assert sorted(counted) == sorted(p.name for p in CONFIGS.glob("*.toml"))
    for name, system in every.items():  # each the system its file defines, read and validated the usual way
        assert system.definition() == read_system_file(CONFIGS / f"{name}.toml").definition()
    assert [n for n, _ in table.items()] == list(every) == list(table)


def test_the_global_table_lists_every_builtin_and_the_messages_are_unchanged():
    assert system_names() == list(builtin_systems()) == sorted(p.stem for p in CONFIGS.glob("*.toml"))
    assert get_system("300w_lp") is SYSTEMS["300w_lp"]
    with pytest.raises(SystemError_) as exc:
        get_system("nope")
    assert str(exc.value) == (
        f"expected a system name ({', '.join(sorted(p.stem for p in CONFIGS.glob('*.toml')))}) or a .toml file, "
        "got 'nope'"
    )


def test_threads_looking_up_one_unread_system_get_one_object():
    table = _table(CONFIGS)
    got, barrier = [], threading.Barrier(4)

    def look():
        barrier.wait()
        got.append(table["whenet"])

    threads = [threading.Thread(target=look) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(got) == 4 and all(g is got[0] for g in got)


def test_a_builtin_file_must_be_named_after_its_system(tmp_path):
    shutil.copy(CONFIGS / "opencv.toml", tmp_path / "opencv_copy.toml")
    table = _table(tmp_path)
    assert list(table) == ["opencv_copy"]
    with pytest.raises(SystemError_, match=r"opencv_copy.toml: name: expected 'opencv_copy' .*, got 'opencv'"):
        table["opencv_copy"]


def test_a_bad_builtin_file_is_one_line_when_used(tmp_path):
    (tmp_path / "broken.toml").write_text('name = "broken"\nframe = 3\n', encoding="utf-8")
    table = _table(tmp_path)
    assert list(table) == ["broken"]  # listed by name, read when used
    with pytest.raises(SystemError_, match="broken.toml: frame: expected a 3x3 array of numbers, got 3"):
        table["broken"]


def test_a_command_reads_only_the_system_it_uses():
    """In a fresh interpreter: the default system of a label file without one is the only file read."""
    code = (
        "import hpe_cli.rotation.systems as s\n"
        "read = []\n"
        "real = s.read_builtin_file\n"
        "s.read_builtin_file = lambda e: (read.append(e.name), real(e))[1]\n"
        "s.get_system('300w_lp'); s.get_system('300w_lp'); s.system_names()\n"
        "print(read)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['300w_lp.toml']"
