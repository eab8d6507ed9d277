"""``--threads N`` on evaluate, convert, audit and augment: the outputs are the same bytes whatever the number.

Tables of several batches (``--batch-size``) so that chunks are really processed side by side, with
predictions in GT order (streamed) and shuffled (key join), every protocol.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import click
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import hpe
from hpe_cli.cli.main import cli
from hpe_cli.cli.options import THREADS_HELP


def _tables(tmp_path, n=9000, shuffled=False):
    rng = np.random.default_rng(7)
    g = np.c_[rng.uniform(-99, 99, n), rng.uniform(-99, 99, n), rng.uniform(-99, 99, n)]
    g[:50, 1] = 90.0  # gimbal lock rows
    p = g + rng.normal(0, 5, (n, 3))
    names = np.array([f"img{k}" for k in range(n)], dtype=object)
    pq.write_table(
        pa.table({"image": names, "pitch": g[:, 0], "yaw": g[:, 1], "roll": g[:, 2]}), tmp_path / "gt.parquet"
    )
    order = rng.permutation(n) if shuffled else np.arange(n)
    pred = pa.table({"image": names[order], "pitch": p[order, 0], "yaw": p[order, 1], "roll": p[order, 2]})
    pq.write_table(pred, tmp_path / "pred.parquet")
    return tmp_path / "gt.parquet", tmp_path / "pred.parquet"


@pytest.mark.parametrize("shuffled", [False, True])
def test_evaluate_same_bytes_for_1_and_2_threads(tmp_path, shuffled):
    gt, pred = _tables(tmp_path, shuffled=shuffled)
    out = {}
    for t in (1, 2, 3):
        d = tmp_path / f"t{t}"
        d.mkdir()
        hpe(
            "evaluate", pred, gt, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "--batch-size", "1000",
            "--json", d / "r.json", "-o", d / "rows.parquet", "--yaw-bins", "30", "--threads", t, "-q",
            ok=True,
        )  # fmt: skip
        rep = json.loads((d / "r.json").read_text())
        assert rep["n"]["pairs"] == 9000
        out[t] = ((d / "r.json").read_bytes(), pq.read_table(d / "rows.parquet"))
    for t in (2, 3):
        assert out[t][0] == out[1][0]
        assert out[t][1].equals(out[1][1])


def test_convert_and_audit_same_bytes_for_1_and_2_threads(tmp_path):
    gt, _ = _tables(tmp_path, n=5000)
    outs = {}
    for t in (1, 2):
        hpe("convert", gt, "-o", tmp_path / f"c{t}.parquet", "--from", "300w_lp", "--to", "6drepnet",
             "--batch-size", "700", "--threads", t, "-q", ok=True)  # fmt: skip
        hpe("audit", gt, "--system", "300w_lp", "--json", tmp_path / f"a{t}.json", "-o", tmp_path / f"a{t}.parquet",
             "--batch-size", "700", "--threads", t, "-q", ok=True)  # fmt: skip
        outs[t] = [pq.read_table(tmp_path / f"{k}{t}.parquet") for k in "ca"]
        outs[t].append(json.loads((tmp_path / f"a{t}.json").read_text()))
    assert outs[1][0].equals(outs[2][0])
    assert outs[1][1].equals(outs[2][1])
    assert outs[1][2] == outs[2][2]


@pytest.mark.parametrize("name", ["evaluate", "convert", "audit", "augment"])
def test_threads_help_says_the_default(name):
    r = hpe(name, "--help")
    assert "--threads N" in r.output
    assert "one per core" in r.output and "os.cpu_count()" in r.output
    opt = next(p for p in cli.get_command(None, name).params if "--threads" in p.opts)
    assert opt.help == THREADS_HELP


def test_threads_must_be_positive(tmp_path):
    gt, pred = _tables(tmp_path, n=10)
    r = hpe("convert", gt, "-o", tmp_path / "c.parquet", "--from", "300w_lp", "--to", "6drepnet", "--threads", "0")  # fmt: skip
    assert r.exit_code == 2 and "--threads" in r.output


def test_augment_same_bytes_for_1_and_2_threads(tmp_path):
    """augment's batch pool (``--threads``): labels, landmarks and boxes moved the same whatever the number."""
    gt, _ = _tables(tmp_path, n=5000)
    for t in (1, 2, 3):
        hpe("augment", gt, "-o", tmp_path / f"g{t}.parquet", "--image-size", "450x450", "--hflip",
             "--batch-size", "700", "--threads", t, "-q", ok=True)  # fmt: skip
    first = pq.read_table(tmp_path / "g1.parquet")
    assert first.num_rows == 5000
    for t in (2, 3):
        assert pq.read_table(tmp_path / f"g{t}.parquet").equals(first)


# --- issue 33 §3: every command that processes rows says how many threads/processes it uses, and takes an option
# to limit them; draw, relabel-agora, biwi and infer give the same bytes whatever the number

ROOT = Path(__file__).resolve().parents[2]
BIWI = ROOT / ".." / "shared" / "realdata" / "biwi" / "db_annotations_subset"
#: the option each row-processing command limits its threads or processes with, and the word its help uses
CORES_OPTION = {
    "convert": ("--threads", "thread"),
    "audit": ("--threads", "thread"),
    "augment": ("--threads", "thread"),
    "evaluate": ("--threads", "thread"),
    "draw": ("--threads", "thread"),
    "relabel-agora": ("--threads", "thread"),
    "biwi": ("--threads", "thread"),
    "infer": ("--threads", "thread"),
    "view": ("--threads", "thread"),
    "export": ("--workers", "process"),
    "relabel-panoptic": ("--workers", "process"),
}


def test_every_row_processing_command_has_a_cores_option():
    from tests.docs.test_cli_consistency import ROW_READERS

    assert sorted(CORES_OPTION) == sorted(ROW_READERS)


@pytest.mark.parametrize("name", sorted(CORES_OPTION))
def test_cores_option_help_names_the_default(name):
    option, word = CORES_OPTION[name]
    cmd = cli.get_command(None, name)
    p = next(p for p in cmd.params if option in p.opts)
    assert isinstance(p.type, click.IntRange) and p.type.min == 1, name
    help_text = " ".join(hpe(name, "--help", ok=True).output.split())
    options_part = help_text[help_text.index("Options:") :]
    block = options_part[options_part.index(f" {option} ") :]
    block = block[: re.search(r" --?[a-z]", block[len(option) + 1 :]).start() + len(option) + 1]  # up to the next
    assert word in block.lower(), (name, block)
    assert "[default: " in block, (name, block)
    if option == "--threads":
        assert p.help == THREADS_HELP and "one per core" in block
    else:
        assert p.show_default and isinstance(p.default, int), name


def _tree_bytes(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


def test_draw_same_bytes_for_1_2_3_threads(tmp_path):
    """Photographs (the AFLW2000 samples), blank canvases with captions, and contact sheets."""
    rng = np.random.default_rng(3)
    n = 40
    ang = rng.uniform(-80, 80, (n, 3))
    table = pa.table(
        {"image": [f"f{k % 25:03d}.png" for k in range(n)], "pitch": ang[:, 0], "yaw": ang[:, 1], "roll": ang[:, 2]}
    )
    pq.write_table(table, tmp_path / "poses.parquet")
    runs = {
        "photos": [ROOT / "sample_data/aflw2000", "--style", "cube", "--annotate"],
        "canvas": [tmp_path / "poses.parquet", "--image-size", "96x64", "--annotate"],
        "sheet": [tmp_path / "poses.parquet", "--image-size", "96x64", "--grid", "--grid-cols", "3", "--tile", "32"],
    }
    for what, args in runs.items():
        out = {}
        for t in (1, 2, 3):
            hpe("draw", *args, "-o", tmp_path / f"{what}{t}", "--threads", t, "-q", ok=True)
            out[t] = _tree_bytes(tmp_path / f"{what}{t}")
        assert len(out[1]) >= (3 if what == "sheet" else 4), what
        assert out[2] == out[1] and out[3] == out[1], what


def test_relabel_agora_same_bytes_for_1_2_3_threads(tmp_path):
    import shutil

    pkl = ROOT / "tests/data/agora/validation_0_withjv.pkl"
    frames = []
    for k in range(3):  # three dataframes (distinct names), fitted side by side
        d = tmp_path / f"in{k}"
        d.mkdir()
        frames.append(shutil.copy(pkl, d / f"validation_{k}_withjv.pkl"))
    out = {}
    for t in (1, 2, 3):
        for fmt, ext in (("table", "parquet"), ("coco", "json")):
            hpe("relabel-agora", *frames, "-o", tmp_path / f"a{t}.{ext}", "--format", fmt,
                "--rejects", tmp_path / f"r{t}{fmt}.csv", "--threads", t, "-q", ok=True)  # fmt: skip
        out[t] = [
            (tmp_path / n).read_bytes() for n in (f"a{t}.parquet", f"a{t}.json", f"r{t}table.csv", f"r{t}coco.csv")
        ]
    assert pq.read_table(tmp_path / "a1.parquet").num_rows > 0
    assert out[2] == out[1] and out[3] == out[1]


def test_biwi_same_bytes_for_1_2_3_threads(tmp_path):
    if not BIWI.is_dir():
        pytest.skip("real BIWI annotations absent")
    out = {}
    for t in (1, 2, 3):
        hpe("biwi", BIWI, "-o", tmp_path / f"b{t}.parquet", "--split", "0.5,0.5", "--split-lists", tmp_path,
            "--overwrite", "--threads", t, "-q", ok=True)  # fmt: skip
        out[t] = (tmp_path / f"b{t}.parquet").read_bytes()
    assert pq.read_table(tmp_path / "b1.parquet").num_rows > 0
    assert out[2] == out[1] and out[3] == out[1]


def test_infer_same_report_for_1_2_3_threads(tmp_path):
    """A data table (pyarrow and OpenCV pools limited) and user code (its child's OMP/MKL/OpenBLAS variables)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    ang = rng.uniform(-60, 60, (300, 3))
    R = Rotation.from_euler("xyz", np.radians(ang[:, [0, 1, 2]])).as_matrix().reshape(-1, 9)
    cols = {f"r{i}{j}": R[:, 3 * i + j] for i in range(3) for j in range(3)}
    pq.write_table(pa.table({"pitch": ang[:, 0], "yaw": ang[:, 1], "roll": ang[:, 2], **cols}), tmp_path / "t.parquet")
    code = tmp_path / "code.py"
    code.write_text(
        "import os\nimport sys\n"
        f"sys.path.insert(0, {str(ROOT / 'tests/fixtures/conventions')!r})\n"
        "from sixdrepnet import get_R as _get_R\n\n\n"
        "def get_R(x, y, z):\n"
        f"    with open({str(tmp_path / 'seen.txt')!r}, 'a') as fh:\n"
        "        fh.write(os.environ.get('OMP_NUM_THREADS', '') + ',' + os.environ.get('MKL_NUM_THREADS', '') + '\\n')\n"
        "    return _get_R(x, y, z)\n"
    )
    out = {}
    for t in (1, 2, 3):
        hpe("infer", tmp_path / "t.parquet", "--json", tmp_path / f"d{t}.json", "--threads", t, "-q", ok=True)
        (tmp_path / "seen.txt").unlink(missing_ok=True)
        hpe("infer", "--callable", f"{code}:get_R", "--args", "pitch,yaw,roll", "--json", tmp_path / f"c{t}.json",
            "--threads", t, "-q", ok=True)  # fmt: skip
        assert set((tmp_path / "seen.txt").read_text().split()) == {f"{t},{t}"}
        out[t] = [(tmp_path / f"{k}{t}.json").read_bytes() for k in "dc"]
    assert json.loads(out[1][1])["fit"] == "exact"
    assert out[2] == out[1] and out[3] == out[1]


@pytest.mark.parametrize("name", ["draw", "relabel-agora", "biwi", "infer"])
def test_threads_zero_is_a_usage_error(name):
    r = hpe(name, "--threads", "0", ROOT / "README.md")
    assert r.exit_code == 2 and "--threads" in r.output


def test_options_objects_check_threads():
    from hpe_cli.errors import UsageError
    from hpe_cli.pipelines.biwi import BiwiOptions
    from hpe_cli.pipelines.draw import DrawOptions
    from hpe_cli.pipelines.infer import InferOptions
    from hpe_cli.pipelines.relabel import RelabelAgoraOptions

    for cls, err in ((DrawOptions, Exception), (RelabelAgoraOptions, ValueError), (BiwiOptions, ValueError),
                     (InferOptions, UsageError)):  # fmt: skip
        assert cls(threads=2).threads == 2
        for bad in (0, -1, 1.5, True, "2"):
            with pytest.raises(err, match="threads"):
                cls(threads=bad)


def test_library_threads_restores_the_pools():
    import cv2

    from hpe_cli.pipelines.pools import library_threads

    before = (cv2.getNumThreads(), pa.cpu_count(), pa.io_thread_count())
    with library_threads(1) as n:
        assert n == 1 and (cv2.getNumThreads(), pa.cpu_count(), pa.io_thread_count()) == (1, 1, 1)
    assert (cv2.getNumThreads(), pa.cpu_count(), pa.io_thread_count()) == before
    with pytest.raises(RuntimeError), library_threads(3):
        raise RuntimeError("boom")
    assert (cv2.getNumThreads(), pa.cpu_count(), pa.io_thread_count()) == before


def test_api_takes_threads_as_the_cli(tmp_path):
    """``threads`` reaches the same options objects from the Python API: the same bytes as the CLI."""
    import hpe_cli as api

    hpe("draw", ROOT / "sample_data/aflw2000", "-o", tmp_path / "cli", "--threads", 1, "-q", ok=True)
    api.draw_file(ROOT / "sample_data/aflw2000", tmp_path / "api", threads=2)
    assert _tree_bytes(tmp_path / "api") == _tree_bytes(tmp_path / "cli")
    pkl = ROOT / "tests/data/agora/validation_0_withjv.pkl"
    hpe("relabel-agora", pkl, "-o", tmp_path / "c.parquet", "--rejects", tmp_path / "c.csv", "--threads", 1, ok=True)
    api.relabel_agora(pkl, tmp_path / "a.parquet", rejects=tmp_path / "a.csv", threads=2)
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "c.parquet").read_bytes()
    rep = api.infer_system(code=f"{ROOT}/tests/fixtures/conventions/sixdrepnet.py:get_R", builder=True, threads=2)
    assert rep["fit"] == "exact"
    if BIWI.is_dir():
        api.biwi_file(BIWI, tmp_path / "b.parquet", threads=2)
        assert pq.read_table(tmp_path / "b.parquet").num_rows > 0


def test_view_same_bytes_for_1_2_3_threads(tmp_path):
    """view's ``--threads`` (thumbnail threads): the same page whatever the number."""
    pages = []
    for w in (1, 2, 3):
        hpe("view", ROOT / "sample_data/aflw2000", "-o", tmp_path / f"v{w}/page.html", "--threads", w, "-q", ok=True)
        pages.append(_tree_bytes(tmp_path / f"v{w}"))
    assert pages[0] and pages[1] == pages[0] and pages[2] == pages[0]
