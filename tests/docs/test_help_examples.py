"""Every example in ``hpe --help`` and each command's ``--help`` runs on the shipped samples, and every line of the
README's tour runs twice.

The help examples name files by what they are (``labels.csv``, ``AFLW2000/``, ``SEQ``, ``preds.csv``); the
scratch folder gives each such name a file made from ``sample_data/`` (``PLACEHOLDERS``, built by ``SETUP``), so the
examples stay readable and still run. The few that need what no sample has (a Dask scheduler, user code that is
not shipped, a dataset only on the real-data disk) are listed in ``NOT_RUN`` with the reason.
"""

from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import doc_examples as dx  # noqa: E402

from conftest import hpe

ROOT = dx.ROOT

#: placeholder name in the examples -> shipped file or folder it stands for (a symlink in the scratch folder)
PLACEHOLDERS = {
    "AFLW2000": "sample_data/aflw2000",
    "300W_LP/AFW": "sample_data/aflw2000",
    "frames": "sample_data/aflw2000",
    "labels.csv": "sample_data/labels_300wlp.csv",
    "poses.csv": "sample_data/labels_300wlp.csv",
    "SEQ": "sample_data/panoptic_160906_pizza1",
    "ROOT/seqA": "sample_data/panoptic_160906_pizza1",
    "ROOT/seqB": "sample_data/panoptic_synth",
    "sixdrepnet.py": "tests/fixtures/conventions/sixdrepnet.py",
    "mycode.py": "tests/fixtures/conventions/stored_values.py",
    "3DDFA_V2/utils/pose.py": "tests/fixtures/conventions/tddfa_v2.py",
    "my_system.toml": "configs/systems/whenet.toml",
}

#: commands run first (in order) to make the other placeholders from the samples
SETUP = [
    "hpe convert AFLW2000/ -o labels.parquet --from 300w_lp --to 300w_lp",
    "hpe convert AFLW2000/ -o preds.csv --from 300w_lp --to 6drepnet",
    "hpe convert AFLW2000/ -o img2pose_preds.csv --from 300w_lp --to img2pose",
    "hpe convert AFLW2000/ -o trinet_raw.csv --from 300w_lp --to trinet",
    "hpe convert AFLW2000/ -o preds.parquet --from 300w_lp --to whenet",
    "hpe convert AFLW2000/ -o gt.parquet --from 300w_lp --to whenet",
    "hpe convert AFLW2000/ -o gt.csv --from 300w_lp --to 300w_lp",
    "hpe convert AFLW2000/ -o preds_in_gt_order.csv --from 300w_lp --to 300w_lp",
    "hpe convert AFLW2000/ -o preds_rad.csv --from 300w_lp --to 6drepnet",
    "hpe evaluate preds.csv AFLW2000/ --pred-system 6drepnet --gt-system 300w_lp -o errors.parquet",
    "hpe relabel-panoptic SEQ -o pizza.parquet --rejects pizza_rejects.csv",
    "hpe relabel-panoptic SEQ -o out/labels.parquet --rejects pizza_rejects2.csv",
    "hpe relabel-panoptic SEQ -o panoptic_labels.parquet --rejects pizza_rejects3.csv",
]

#: examples whose point is a failure exit on these samples: line -> (exit code, text the error names)
FAILS_ON_PURPOSE = {"hpe audit labels.csv --system whenet --gimbal-tol 2 --strict": (1, "3 of 204 rows flagged")}

#: examples not run here, with the reason
NEEDS = {
    "agora": "AGORA's dataframes are not shipped (tests/readers and the realdata tests run relabel-agora)",
    "biwi": "BIWI is not shipped (the realdata tests run hpe biwi on hpdb/ and db_annotations.tgz)",
    "dask": "needs a running Dask scheduler (tests/relabel test --scheduler with a local cluster)",
    "images": "the Panoptic sample ships no frames or videos (the realdata tests export with --images)",
    "user code": "names user code that is not shipped (tests/fixtures/conventions has the shipped ones)",
}
NOT_RUN = {
    "hpe relabel-panoptic SEQ -o labels.csv --cameras 00_00,00_08 --frames 1000:2000 --every 10": "the sample has "
    "three frames (1147, 3476, 5777): the frame filter finds none",
    "hpe relabel-panoptic ROOT -o labels.parquet --frame crop --cameras whenet-haggling --min-change 5": "WHENet's "
    "haggling cameras are not in the synthetic sample's calibration (ROOT/seqB)",
    "hpe relabel-panoptic ROOT -o labels.parquet --scheduler tcp://head:8786 --resume": NEEDS["dask"],
    "hpe export labels.parquet -o out/whenet --layout whenet --images ROOT --scheduler tcp://head:8786 --resume": NEEDS[
        "dask"
    ],
    "hpe view corrected.parquet legacy.parquet -o compare/ --images panoptic/ --rejects missing.csv": NEEDS["images"],
    "hpe view panoptic_whenet.parquet -o page/ --images panoptic/ --also-in 300w_lp,3ddfa_v2": NEEDS["images"],
    "hpe relabel-agora validation_*_withjv.pkl -o agora_val.parquet": NEEDS["agora"],
    "hpe relabel-agora train_0_withjv.pkl -o train.json --format coco --image-size 1280x720": NEEDS["agora"],
    "hpe relabel-agora val_0_withjv.pkl -o annotation.txt --legacy-whenet --max-rmse inf": NEEDS["agora"],
    "hpe relabel-agora val_0_withjv.pkl -o labels.csv --system 6drepnet --rejects rejects.csv": NEEDS["agora"],
    "hpe relabel-agora val_0_withjv.pkl -o crops.parquet --frame crop": NEEDS["agora"],
    "hpe augment aflw_lm.parquet -o aflw_v.parquet --image-size 450x450 --vflip --landmarks aflw21": "needs AFLW's "
    "21 landmarks (the AFLW2000-3D sample has the 68 of iBUG)",
    "hpe infer --callable mylib.pose:euler_to_matrix --args roll,pitch,yaw --degrees -o mine.toml": NEEDS["user code"],
    "hpe biwi hpdb/ -o biwi.parquet": NEEDS["biwi"],
    "hpe biwi hpdb/ -o biwi_rgb.parquet --camera rgb --system 300w_lp": NEEDS["biwi"],
    "hpe biwi db_annotations.tgz -o biwi.parquet --camera rgb --calibration hpdb/": NEEDS["biwi"],
    "hpe biwi hpdb/ -o biwi.parquet --split 0.7,0.3 --seed 0 --split-lists splits/": NEEDS["biwi"],
    "hpe biwi db_annotations/ -o biwi.parquet --rejects biwi_rejects.csv": NEEDS["biwi"],
    "hpe export pizza.parquet -o out/whenet --layout whenet --images SEQ --rejects rej.csv": NEEDS["images"],
    "hpe export a.parquet b.parquet -o out/dmhp --layout directmhp --drop-images-with-rejects --rejects rej.csv": NEEDS[
        "images"
    ],
    "hpe export pizza.parquet -o out/360 --layout 6drepnet --trainer 6drepnet360 --images SEQ --rejects rej.csv": NEEDS[
        "images"
    ],
    "hpe export pizza.parquet -o out/dmhp --layout directmhp --split camera:train=0.75,val=0.25 --images SEQ": NEEDS[
        "images"
    ],
    "hpe export pizza.parquet -o out/hf --layout hf --system 6drepnet --min-change 5 --balance yaw:10:500": NEEDS[
        "images"
    ],
}


def _files(tmp: Path) -> None:
    """The placeholders that are small files written here rather than made by a command."""
    import pandas as pd

    df = pd.read_csv(ROOT / "sample_data" / "labels_300wlp.csv")
    rad = df.copy()
    rad[["pitch", "yaw", "roll"]] = np.radians(rad[["pitch", "yaw", "roll"]])
    rad.to_csv(tmp / "rad.csv", index=False)
    (tmp / "messy.csv").write_text(
        (ROOT / "sample_data" / "labels_300wlp.csv").read_text() + "bad.jpg,not a number,1,2,3,4,5\n"
    )
    # the TOML example of docs/commands/systems.md, as a user would copy it
    page = (ROOT / "docs" / "commands" / "systems.md").read_text(encoding="utf-8")
    toml = re.search(r"```toml\n(name = \"my_quaternions\".*?)```", page, re.S).group(1)
    (tmp / "my_quaternions.toml").write_text(toml)


def help_examples() -> list[tuple[str, str]]:
    """(command, example line) of every example printed by ``hpe --help`` and ``hpe COMMAND --help``: the
    lines under ``Examples:``."""
    from hpe_cli.cli.main import COMMANDS

    def examples(text):
        block = text.split("Examples:", 1)[1] if "Examples:" in text else ""
        block = block.split("\nOptions:", 1)[0]
        return dx.commands(block)

    out = [("hpe", line) for line in examples(hpe("--help").output)]
    for name in COMMANDS:
        text = hpe(name, "--help", terminal_width=400).output
        out += [(name, line) for line in examples(text)]
    return out


EXAMPLES = help_examples()


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("help-examples")
    for name in ("sample_data", "tests", "configs"):
        (tmp / name).symlink_to(ROOT / name)
    for name, target in PLACEHOLDERS.items():
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp / name).symlink_to(ROOT / target)
    _files(tmp)
    for cmd in SETUP:
        code, out = dx.run(cmd + " -q", tmp)
        assert code == 0, f"{cmd}: {out}"
    _derived(tmp)
    return tmp


def _derived(tmp: Path) -> None:
    """Placeholders made from the SETUP outputs: extra columns a few examples name."""
    import pandas as pd
    from scipy.spatial.transform import Rotation

    preds = pd.read_csv(tmp / "preds.csv")
    rv = Rotation.from_matrix(preds[[f"r{i}{j}" for i in range(3) for j in range(3)]].to_numpy().reshape(-1, 3, 3))
    rotvec = preds[["image", "pitch", "yaw", "roll"]].copy()
    rotvec[["rx", "ry", "rz"]] = rv.as_rotvec()
    rotvec.to_csv(tmp / "preds_rotvec.csv", index=False)
    for name in ("preds.csv", "gt.csv"):  # evaluate --key image,person_id --by sequence
        t = pd.read_csv(tmp / name)
        t["person_id"], t["sequence"] = 0, ["a", "a", "b", "b"][: len(t)]
        t.to_csv(tmp / name, index=False)
    rad = preds[["image", "pitch", "yaw", "roll"]].copy()  # export --radians: a head box and the images beside it
    rad[["pitch", "yaw", "roll"]] = np.radians(rad[["pitch", "yaw", "roll"]])
    rad[["bbox_x", "bbox_y", "bbox_w", "bbox_h"]] = [100.0, 100.0, 250.0, 250.0]
    rad.to_csv(tmp / "preds_rad.csv", index=False)
    for jpg in (ROOT / "sample_data" / "aflw2000").glob("*.jpg"):
        (tmp / jpg.name).symlink_to(jpg)


def _copy(scratch: Path, dest: Path, line: str) -> Path:
    """A folder of links to everything in ``scratch`` but the example's outputs: each example writes its own."""
    argv = shlex.split(line)
    outputs = {argv[i + 1].rstrip("/") for i, a in enumerate(argv[:-1]) if a in ("-o", "--output", "--json")}
    dest.mkdir()
    for entry in scratch.iterdir():
        if entry.name not in outputs:
            (dest / entry.name).symlink_to(entry.resolve() if entry.is_symlink() else entry)
    return dest


def test_examples_found():
    assert len(EXAMPLES) > 60
    assert all(line in {e[1] for e in EXAMPLES} for line in NOT_RUN), "a NOT_RUN entry is no longer an example"


@pytest.mark.parametrize("where,line", EXAMPLES, ids=[f"{w}:{i}" for i, (w, _) in enumerate(EXAMPLES)])
def test_help_example_runs_on_the_samples(where, line, scratch, tmp_path):
    if line in NOT_RUN:
        pytest.skip(NOT_RUN[line])
    cmd = re.sub(r"\s>\s*\S+$", "", line)  # `> systems.json`: stdout is captured anyway
    code, out = dx.run(cmd, _copy(scratch, tmp_path / "run", cmd))
    expected, says = FAILS_ON_PURPOSE.get(line, (0, ""))
    assert code == expected and says in out, f"hpe {where} --help: {line!r} exited {code}:\n{out}"


def readme_tour() -> list[str]:
    """The command lines of the README's "A short tour" block (and its Quick start ``hpe`` line)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    tour = text.split("## A short tour", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    quick = text.split("## Quick start", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    quick_lines = [c.split("&&", 1)[1].strip() for c in quick.splitlines() if "&& hpe " in c]
    return quick_lines + dx.commands(tour)


def getting_started_tour() -> list[str]:
    """The marked examples of docs/getting-started.md, in order (the newcomer's page)."""
    return [cmd for ex in dx.examples(dx.DOCS / "getting-started.md") for cmd in ex.commands]


def test_getting_started_runs_twice(tmp_path):
    """The getting-started page's commands, run twice in one folder as a reader following it would."""
    lines = getting_started_tour()
    assert len(lines) >= 8
    for name in ("sample_data", "tests", "configs"):
        (tmp_path / name).symlink_to(ROOT / name)
    for round_ in (1, 2):
        for line in lines:
            code, out = dx.run(line, tmp_path)
            assert code == 0, f"getting-started.md, run {round_}: {line!r} exited {code}:\n{out}"


def test_readme_tour_runs_twice(tmp_path):
    """Every tour line runs from the repository root on the shipped samples, and again (a newcomer runs the tour
    twice): outputs go to out/ and the lines that write have --overwrite."""
    lines = readme_tour()
    assert len(lines) >= 10
    for name in ("sample_data", "tests", "configs"):
        (tmp_path / name).symlink_to(ROOT / name)
    for round_ in (1, 2):
        for line in lines:
            code, out = dx.run(line, tmp_path)
            assert code == 0, f"README tour, run {round_}: {line!r} exited {code}:\n{out}"
    assert {p.name for p in (tmp_path / "out").iterdir()} >= {"labels_6d.parquet", "drawn", "fsa", "pizza.parquet"}
