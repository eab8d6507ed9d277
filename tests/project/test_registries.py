"""One table per extension point: no name list copied by hand, and a plug-in entry works end to end.

(a) No tuple/list/set literal (nor dict keys) in ``hpe_cli/``, ``tests/`` or the Python blocks of ``docs/`` copies a registry's
names. A literal is a copy when it holds at least two names of one registry and at least three quarters of
them: a selection of two protocols for a test, or a ``(from, to)`` pair of systems that happen to share names with
layouts and protocols (``whenet``, ``6drepnet``), is not a copy; the old ``LAYOUTS`` tuples and the 16-name
protocol tuple of ``cli/evaluate.py`` were.

(b) A dummy reader, export layout and protocol registered at run time through the public registration calls run
through the CLI: reader -> ``hpe convert``, layout -> ``hpe export``, protocol -> ``hpe evaluate --protocol``.
"""

from __future__ import annotations

import ast
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import hpe as hpe_cmd
from hpe_cli.cli.main import cli
from hpe_cli.io.dataset_readers import READERS, input_format_names, register_reader
from hpe_cli.io.export import LAYOUTS
from hpe_cli.io.export.base import Layout
from hpe_cli.io.images import IMAGE_LAYOUTS
from hpe_cli.io.readers import frame_source
from hpe_cli.metrics.protocols import PROTOCOLS, ProtocolRows, register_protocol
from hpe_cli.rotation.decoders import DECODERS
from hpe_cli.rotation.systems import SYSTEMS

ROOT = Path(__file__).resolve().parents[2]
AFLW = ROOT / "sample_data" / "aflw2000"

#: every name table a literal could copy (the input formats are a view of READERS)
TABLES = {
    "READERS": lambda: READERS.names(),
    "input formats": input_format_names,
    "LAYOUTS": lambda: LAYOUTS.names(),
    "PROTOCOLS": lambda: PROTOCOLS.names(),
    "DECODERS": lambda: DECODERS.names(),
    "IMAGE_LAYOUTS": lambda: IMAGE_LAYOUTS.names(),
    "SYSTEMS": lambda: SYSTEMS.names(),
}


def run(*args):
    return hpe_cmd(*args)


# ---------------------------------------------------------------------------------------------- (a) no copies
def _python_sources():
    for folder in ("hpe_cli", "tests"):
        for f in sorted((ROOT / folder).rglob("*.py")):
            yield f, f.read_text(encoding="utf-8")
    for f in sorted((ROOT / "docs").rglob("*.md")):
        text = f.read_text(encoding="utf-8")
        for k, block in enumerate(re.findall(r"```python\n(.*?)```", text, flags=re.S)):
            yield Path(f"{f}#python-block-{k + 1}"), block


def copies(source: str, tables: dict) -> list:
    """``(line, table, names)`` of the literals in ``source`` that copy a table's names (see the module doc)."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return []
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            items = node.elts
        elif isinstance(node, ast.Dict):  # a table keyed by the names (FORMAT_SYSTEMS was one)
            items = [k for k in node.keys if k is not None]
        else:
            continue
        strings = {e.value for e in items if isinstance(e, ast.Constant) and isinstance(e.value, str)}
        for table, names in tables.items():
            common = strings & set(names)
            if len(common) >= 2 and len(common) >= math.ceil(0.75 * len(names)):
                out.append((node.lineno, table, sorted(common)))
    return out


def test_no_name_list_repeats_a_registry():
    tables = {k: names() for k, names in TABLES.items()}
    assert all(len(v) >= 2 for v in tables.values()), tables
    found = [
        f"{f.relative_to(ROOT)}:{line}: {table} {names}"
        for f, src in _python_sources()
        for line, table, names in copies(src, tables)
    ]
    assert not found, "name lists copied by hand (read the registry instead):\n" + "\n".join(found)


def test_the_scan_finds_a_copy():
    """The rule catches what was there before: a copy of the layout names, a stale protocol list."""
    layouts = list(LAYOUTS.names())
    tables = {k: names() for k, names in TABLES.items()}
    assert copies(f"LAYOUTS = {tuple(layouts)!r}", tables)
    assert copies(f"X = {list(PROTOCOLS.names())[:-1]!r}", tables)  # one protocol missing: still a copy
    assert copies(f"SYSTEMS = {dict.fromkeys(input_format_names())!r}", tables)  # a dict keyed by the names
    assert not copies('PAIR = ("whenet", "6drepnet")', tables)  # a pair of systems


def test_help_reads_no_table():
    """``hpe --help`` imports the command modules, never the modules that fill the tables."""
    code = (
        "import sys\nfrom click.testing import CliRunner\nfrom hpe_cli.cli.main import cli\n"
        "r = CliRunner().invoke(cli, ['--help'])\nassert r.exit_code == 0, r.output\n"
        "heavy = ['hpe_cli.metrics.protocols', 'hpe_cli.io.export.builtin', 'hpe_cli.io.readers_builtin',"
        " 'hpe_cli.rotation.decoders', 'hpe_cli.io.dataset_readers']\n"
        "print([m for m in heavy if m in sys.modules])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out


@pytest.mark.parametrize(
    "command, option, names",
    [
        ("export", "--layout", lambda: LAYOUTS.names()),
        ("evaluate", "--protocol", lambda: PROTOCOLS.names() + ("all",)),
        ("convert", "--decoder", lambda: DECODERS.names()),
        ("audit", "--decoder", lambda: DECODERS.names()),
        ("convert", "--input-format", input_format_names),
    ],
)
def test_choices_read_the_registry(command, option, names):
    params = {o: p for p in cli.get_command(None, command).params for o in p.opts}
    assert tuple(params[option].type.choices) == tuple(names())


# ---------------------------------------------------------------------------------------------- (b) plug-ins
def _labels(n=12, seed=3):
    rng = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "image": [f"img{i:02d}.jpg" for i in range(n)],
            "pitch": rng.uniform(-60, 60, n),
            "yaw": rng.uniform(-80, 80, n),
            "roll": rng.uniform(-50, 50, n),
        }
    )


def _open_dummy(path, *, batch_size, with_lines=False):
    """The dummy format: ``image pitch yaw roll`` lines after a ``DUMMY`` line (a format hpe does not know)."""
    lines = Path(path).read_text().splitlines()
    assert lines[0] == "DUMMY"
    rows = [ln.split() for ln in lines[1:]]
    frame = pd.DataFrame(
        {
            "image": [r[0] for r in rows],
            **{c: np.array([float(r[k + 1]) for r in rows]) for k, c in enumerate(("pitch", "yaw", "roll"))},
        }
    )
    return frame_source(Path(path), frame, batch_size, with_lines)


def test_dummy_reader_through_convert(tmp_path):
    labels = _labels()
    dummy = tmp_path / "labels.dummy"
    dummy.write_text("DUMMY\n" + "".join(f"{r.image} {r.pitch!r} {r.yaw!r} {r.roll!r}\n" for r in labels.itertuples()))
    reader = register_reader("dummy", lambda p: p.suffix == ".dummy", key=("image",), doc="a test format")
    try:
        reader(_open_dummy)
        assert READERS["dummy"].open is _open_dummy
        res = run("convert", dummy, "-o", tmp_path / "out.csv", "--from", "300w_lp", "--to", "scipy_zyx", "-q")
        assert res.exit_code == 0, res.output
    finally:
        READERS.unregister("dummy")
    # oracle: the same labels as a plain CSV, through hpe's own CSV reader, give the same output
    labels.to_csv(tmp_path / "labels.csv", index=False)
    res = run("convert", tmp_path / "labels.csv", "-o", tmp_path / "ref.csv", "--from", "300w_lp", "--to", "scipy_zyx")
    assert res.exit_code == 0, res.output
    out, ref = pd.read_csv(tmp_path / "out.csv"), pd.read_csv(tmp_path / "ref.csv")
    assert out["image"].tolist() == labels["image"].tolist()
    pd.testing.assert_frame_equal(out, ref)
    # and the stored matrices are proper rotations SciPy accepts
    got = out[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3)
    np.testing.assert_allclose(Rotation.from_matrix(got).as_matrix(), got, atol=1e-9)


def test_dummy_reader_must_detect(tmp_path):
    """Without the registration the same file is not a table hpe reads: the reader is what made it work."""
    dummy = tmp_path / "labels.dummy"
    dummy.write_text("DUMMY\nimg00.jpg 1 2 3\n")
    res = run("convert", dummy, "-o", tmp_path / "out.csv", "--from", "300w_lp", "--to", "whenet", "-q")
    assert res.exit_code != 0


class DummyLayout(Layout):
    """One crop per head under ``<split>/``, and ``index.txt``: ``name pitch yaw roll`` per crop."""

    name = "dummy"
    system = "300w_lp"
    loader = "tests/project/test_registries.py (DummyLayout)"

    def finish(self, exported, final_root):
        names = self.relpath(exported, "train")
        angles = exported[["pitch", "yaw", "roll"]].to_numpy()
        text = "".join(
            f"{exported['split'].iloc[k]}/{n} {a[0]:.6f} {a[1]:.6f} {a[2]:.6f}\n"
            for k, (n, a) in enumerate(zip(names, angles))
        )
        (self.root / "index.txt").write_text(text)
        return [f"index.txt: {len(names)} crops"]


@pytest.mark.skipif(not AFLW.is_dir(), reason="sample_data/aflw2000 not available")
def test_dummy_layout_through_export(tmp_path):
    out = tmp_path / "out"
    with LAYOUTS.registered("dummy", DummyLayout):
        res = run("export", AFLW, "-o", out, "--layout", "dummy", "-q")
        assert res.exit_code == 0, res.output
    assert "dummy" not in LAYOUTS
    summary = json.loads((out / "export.json").read_text())
    assert summary["layout"] == "dummy" and summary["read_by"] == DummyLayout.loader
    index = (out / "index.txt").read_text().splitlines()
    assert len(index) == summary["exported"] == len(list(AFLW.glob("*.mat")))
    for line in index:
        rel, *angles = line.split()
        assert (out / rel).is_file(), rel
        # oracle: the .mat file's own Pose_Para (radians, pitch yaw roll) read by SciPy's loadmat
        from scipy.io import loadmat

        stem = Path(rel).stem
        pose = loadmat(AFLW / f"{stem}.mat")["Pose_Para"][0, :3] * 180 / np.pi
        np.testing.assert_allclose([float(a) for a in angles], pose, atol=1e-5)


@pytest.mark.skipif(not AFLW.is_dir(), reason="sample_data/aflw2000 not available")
def test_dummy_layout_unknown_without_registration(tmp_path):
    res = hpe_cmd("export", AFLW, "-o", tmp_path / "o", "--layout", "dummy")
    assert res.exit_code == 2 and "'dummy' is not one of" in res.output


def test_dummy_protocol_through_evaluate(tmp_path):
    gt = _labels(20, seed=1)
    pred = gt.copy()
    pred["yaw"] += 2.0  # every prediction 2 degrees off in yaw
    gt.to_csv(tmp_path / "gt.csv", index=False)
    pred.to_csv(tmp_path / "pred.csv", index=False)

    def yaw_only(pair):
        p, g = pair.written("300w_lp", "pred")[0], pair.written("300w_lp", "gt")[0]
        err = np.abs(p - g)
        return ProtocolRows(err, np.ones(pair.n, dtype=bool))

    try:
        register_protocol("dummy", "300w_lp", "|d| per angle as written", "none", "tests/project/test_registries.py")(
            yaw_only
        )
        res = run(
            "evaluate",
            tmp_path / "pred.csv",
            tmp_path / "gt.csv",
            "--pred-system",
            "300w_lp",
            "--gt-system",
            "300w_lp",
            "--protocol",
            "dummy",
            "--json",
            tmp_path / "report.json",
            "-q",
        )
        assert res.exit_code == 0, res.output
    finally:
        PROTOCOLS.unregister("dummy")
    report = json.loads((tmp_path / "report.json").read_text())
    dummy = report["protocols"]["dummy"]
    assert dummy["source"] == "tests/project/test_registries.py"
    np.testing.assert_allclose([dummy["pitch"], dummy["yaw"], dummy["roll"]], [0.0, 2.0, 0.0], atol=1e-9)


def test_a_broken_plugin_is_one_line(tmp_path):
    bad = tmp_path / "bad_plugin.py"
    bad.write_text("raise RuntimeError('boom')\n")
    res = hpe_cmd("systems", env={"HPE_PLUGINS": str(bad)})
    assert res.exit_code == 1
    assert res.output.strip().splitlines() == [f"Error: HPE_PLUGINS: {bad}: cannot load it: RuntimeError: boom"]
    res = hpe_cmd("systems", env={"HPE_PLUGINS": str(tmp_path / "missing.py")})
    assert res.exit_code == 1 and "expected a Python file, got no such file" in res.output


def _first_cells(page: str, header: str) -> list:
    """The first-column names (backquoted, first word) of the Markdown table under the header row ``header``."""
    text = (ROOT / "docs" / page).read_text(encoding="utf-8")
    table = text.split(header + "\n")[1].split("\n\n")[0]
    return list(dict.fromkeys(re.findall(r"^\| `([^` ]+)[^`]*` \|", table, flags=re.M)))


def test_docs_tables_list_the_registries():
    """The docs tables of export layouts and of --input-format lists name exactly the registries' entries."""
    assert tuple(_first_cells("commands/export.md", "| layout | files | trainer code followed |")) == LAYOUTS.names()
    assert tuple(_first_cells("commands/columns.md", "| format | file | layout | followed |")) == input_format_names()
