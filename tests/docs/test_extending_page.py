"""docs/extending.md: every worked example is taken from the page, loaded through ``HPE_PLUGINS`` and run through
the CLI (checked against an independent result), and the page's table of built-in readers is the registry's."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.io import loadmat

from conftest import hpe as hpe_cmd
from hpe_cli.io.dataset_readers import READERS
from hpe_cli.io.export import LAYOUTS
from hpe_cli.metrics.protocols import PROTOCOLS
from hpe_cli.rotation.decoders import DECODERS
from hpe_cli.rotation.systems import SYSTEMS

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "extending.md"
AFLW = ROOT / "sample_data" / "aflw2000"
needs_sample = pytest.mark.skipif(not AFLW.is_dir(), reason="sample_data/aflw2000 not available")


def page_examples() -> dict:
    """``file name -> code`` of the page's ``<!-- extending-example: NAME -->`` Python blocks."""
    text = PAGE.read_text(encoding="utf-8")
    return dict(re.findall(r"<!-- extending-example: (\S+) -->\n```python\n(.*?)```", text, flags=re.S))


@pytest.fixture
def plugin(tmp_path):
    """Write the page's example ``name`` into ``tmp_path``; run ``hpe ARGS`` with it in ``HPE_PLUGINS``."""
    made = []

    def make(name, table, entry):
        path = tmp_path / name
        path.write_text(page_examples()[name], encoding="utf-8")
        made.append((table, entry))

        def run(*args):
            res = hpe_cmd(*args, env={"HPE_PLUGINS": str(path)})
            assert res.exit_code == 0, res.output
            return res

        return run

    yield make
    for table, entry in made:
        table.unregister(entry)


def hpe(*args):
    res = hpe_cmd(*args)
    assert res.exit_code == 0, res.output
    return res


def test_the_page_has_every_example():
    assert set(page_examples()) == {"my_reader.py", "my_layout.py", "my_protocol.py", "my_decoder.py", "my_system.py"}


def test_reader_example(tmp_path, plugin):
    run = plugin("my_reader.py", READERS, "poselist")
    rows = [("img0.jpg", 10.0, 20.0, 5.0), ("img1.jpg", -5.0, 30.0, 2.0), ("img2.jpg", 0.5, -70.0, -12.0)]
    (tmp_path / "labels.poses").write_text("POSELIST\n" + "".join(f"{i} {p} {y} {r}\n" for i, p, y, r in rows))
    run("convert", tmp_path / "labels.poses", "-o", tmp_path / "out.csv", "--to", "whenet", "-q")
    # oracle: the same labels as a CSV through hpe's own CSV reader, --from 300w_lp (the reader's system)
    pd.DataFrame(rows, columns=["image", "pitch", "yaw", "roll"]).to_csv(tmp_path / "ref_in.csv", index=False)
    hpe("convert", tmp_path / "ref_in.csv", "-o", tmp_path / "ref.csv", "--from", "300w_lp", "--to", "whenet", "-q")
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "out.csv"), pd.read_csv(tmp_path / "ref.csv"))


@needs_sample
def test_layout_example(tmp_path, plugin):
    run = plugin("my_layout.py", LAYOUTS, "list")
    run("export", AFLW, "-o", tmp_path / "out", "--layout", "list", "-q")
    lines = (tmp_path / "out" / "list.txt").read_text().splitlines()
    assert len(lines) == len(list(AFLW.glob("*.mat")))
    hpe("convert", AFLW, "-o", tmp_path / "whenet.csv", "--from", "300w_lp", "--to", "whenet", "-q")
    want = pd.read_csv(tmp_path / "whenet.csv").set_index(
        pd.read_csv(tmp_path / "whenet.csv")["file"].map(lambda f: Path(f).stem)
    )
    for line in lines:
        rel, *angles = line.split()
        assert (tmp_path / "out" / rel).is_file(), rel
        np.testing.assert_allclose(
            [float(a) for a in angles], want.loc[Path(rel).stem, ["pitch", "yaw", "roll"]], atol=1e-4
        )


def test_protocol_example(tmp_path, plugin):
    run = plugin("my_protocol.py", PROTOCOLS, "plain-abs")
    rng = np.random.default_rng(5)
    gt = pd.DataFrame(
        {
            "image": [f"i{k}.jpg" for k in range(30)],
            "pitch": rng.uniform(-50, 50, 30),
            "yaw": rng.uniform(-80, 80, 30),
            "roll": rng.uniform(-40, 40, 30),
        }
    )
    pred = gt.copy()
    pred[["pitch", "yaw", "roll"]] += rng.normal(0, 3, (30, 3))
    gt.to_csv(tmp_path / "gt.csv", index=False)
    pred.to_csv(tmp_path / "preds.csv", index=False)
    run(
        "evaluate",
        tmp_path / "preds.csv",
        tmp_path / "gt.csv",
        "--protocol",
        "plain-abs",
        "--json",
        tmp_path / "report.json",
        "--pred-system",
        "300w_lp",
        "--gt-system",
        "300w_lp",
        "-q",
    )
    got = json.loads((tmp_path / "report.json").read_text())["protocols"]["plain-abs"]
    want = np.abs(pred[["pitch", "yaw", "roll"]].to_numpy() - gt[["pitch", "yaw", "roll"]].to_numpy()).mean(0)
    np.testing.assert_allclose([got["pitch"], got["yaw"], got["roll"]], want, atol=1e-9)


@needs_sample
def test_decoder_example(tmp_path, plugin):
    run = plugin("my_decoder.py", DECODERS, "scipy-xyz")
    run(
        "convert",
        AFLW,
        "-o",
        tmp_path / "aflw.csv",
        "--from",
        "300w_lp",
        "--to",
        "300w_lp",
        "--decoder",
        "scipy-xyz",
        "-q",
    )
    out = pd.read_csv(tmp_path / "aflw.csv")
    for _, row in out.iterrows():  # oracle: Pose_Para itself (radians), read by SciPy
        pose = loadmat(AFLW / Path(row["file"]).name)["Pose_Para"][0, :3] * 180 / np.pi
        np.testing.assert_allclose(
            row[["decoder_pitch", "decoder_yaw", "decoder_roll"]].to_numpy(float), pose, atol=1e-6
        )


def test_system_example(tmp_path, plugin):
    toml = (ROOT / "configs" / "systems" / "scipy_zyx.toml").read_text().replace('"scipy_zyx"', '"my_zyx"')
    (tmp_path / "my_zyx.toml").write_text(toml)
    run = plugin("my_system.py", SYSTEMS, "my_zyx")
    pd.DataFrame({"image": ["a", "b"], "pitch": [10.0, -30.0], "yaw": [20.0, 60.0], "roll": [5.0, 1.0]}).to_csv(
        tmp_path / "labels.csv", index=False
    )
    run("convert", tmp_path / "labels.csv", "-o", tmp_path / "zyx.csv", "--from", "300w_lp", "--to", "my_zyx", "-q")
    hpe("convert", tmp_path / "labels.csv", "-o", tmp_path / "ref.csv", "--from", "300w_lp", "--to", "scipy_zyx", "-q")
    cols = [f"r{i}{j}" for i in range(3) for j in range(3)] + ["pitch", "yaw", "roll"]
    np.testing.assert_allclose(pd.read_csv(tmp_path / "zyx.csv")[cols], pd.read_csv(tmp_path / "ref.csv")[cols])


def test_readers_table_is_the_registry():
    text = PAGE.read_text(encoding="utf-8")
    section = text.split("The built-in readers, in the order they are asked:")[1].split("\n## ")[0]
    listed = re.findall(r"^\| `([^`]+)` \|", section, flags=re.M)
    assert tuple(listed) == READERS.names()
    for name in listed:
        system = READERS[name].system
        row = re.search(rf"^\| `{re.escape(name)}` \| (.*?) \|", section, flags=re.M).group(1)
        assert row == (f"`{system}`" if system else "the file's"), name
