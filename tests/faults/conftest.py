"""Shared helpers of the fault-injection suite: one small valid run per command, and the checks every
fault must pass (exit code, one error line naming the file, no traceback, no partial output or temp
files, inputs unchanged)."""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]
SYNTH = ROOT / "sample_data" / "panoptic_synth"
AGORA_PKL = ROOT / "tests" / "data" / "agora" / "validation_0_withjv.pkl"
AFLW = ROOT / "sample_data" / "aflw2000"
FIX = ROOT / "tests" / "fixtures" / "conventions"
TEMP_MARK = ".hpe-"


def tree(folder: Path) -> dict:
    """relative path -> sha256 of every file under ``folder`` (symlinks as their target text)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            p = Path(root) / name
            rel = os.fsdecode(p.relative_to(folder))
            if p.is_symlink():
                out[rel] = "link:" + os.readlink(p)
            elif p.is_file():
                out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
            elif p.is_dir():
                out[rel] = "dir"
    return out


def temp_files(folder: Path) -> list:
    return [os.path.join(r, n) for r, ds, fs in os.walk(folder) for n in ds + fs if n.startswith(TEMP_MARK)]


def check_failed(res, must_name=None, codes=(1,)):
    """One error line (naming ``must_name``), an expected code, no traceback."""
    out = res.output
    assert res.exit_code in codes, out
    assert "Traceback" not in out and "internal error" not in out, out
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), repr(res.exception)
    errors = [line for line in out.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1, out
    if must_name is not None:
        assert str(must_name) in errors[0], (must_name, out)
    assert TEMP_MARK not in errors[0], out
    return errors[0]


def make_images(folder: Path, names, size=(40, 30)):
    folder.mkdir(parents=True, exist_ok=True)
    for n in names:
        cv2.imwrite(str(folder / n), np.full((size[1], size[0], 3), 90, np.uint8))


class Case:
    """A valid run of one command on small inputs in ``tmp``.

    ``args(outputs)`` builds the command line from a dict of output paths
    (option -> path); ``inputs`` are the files the run reads; ``rows`` the
    number of input rows when accounting applies.
    """

    def __init__(self, name, tmp: Path):
        self.name, self.tmp = name, tmp
        build = getattr(self, "_" + name.replace("-", "_"))
        self.inputs, self.outputs, self._args = build(tmp)

    @property
    def file_option(self) -> str:
        """The option of the main file output (draw writes a folder: its rejects file; infer: --json,
        since -o must end in .toml)."""
        return {"draw": "--rejects", "export": "--rejects", "view": "--rejects", "infer": "--json"}.get(self.name, "-o")

    def args(self, **outputs):
        outs = {**self.outputs, **outputs}
        return self._args(outs)

    # each builder returns (inputs, {option: default output path}, args(outs) -> list)
    def _convert(self, t):
        src = t / "in.csv"
        pd.DataFrame({"id": [1, 2, 3], "pitch": [1.0, 2, 3], "yaw": [10.0, -20, 30], "roll": [0.0, 5, -5]}).to_csv(
            src, index=False
        )
        return (
            [src],
            {"-o": t / "out.csv", "--rejects": t / "rej.csv"},
            lambda o: [
                "convert",
                src,
                "-o",
                o["-o"],
                "--from",
                "300w_lp",
                "--to",
                "6drepnet",
                "--rejects",
                o["--rejects"],
            ],
        )

    def _systems(self, t):
        return [], {}, lambda o: ["systems"]

    def _relabel_panoptic(self, t):
        seq = t / "seq"
        shutil.copytree(SYNTH, seq)
        return (
            [seq / f"calibration_{SYNTH.name}.json"],
            {"-o": t / "labels.csv", "--rejects": t / "rej.csv"},
            lambda o: [
                "relabel-panoptic",
                seq,
                "-o",
                o["-o"],
                "--rejects",
                o["--rejects"],
                "--frames",
                "100:103",
                "-q",
            ],
        )

    def _relabel_agora(self, t):
        pkl = t / "agora.pkl"
        shutil.copy(AGORA_PKL, pkl)
        return (
            [pkl],
            {"-o": t / "labels.csv", "--rejects": t / "rej.csv"},
            lambda o: ["relabel-agora", pkl, "-o", o["-o"], "--rejects", o["--rejects"], "-q"],
        )

    def _audit(self, t):
        src = t / "in.csv"
        pd.DataFrame({"pitch": [1.0, 2, 3], "yaw": [10.0, -20, 30], "roll": [0.0, 5, -5]}).to_csv(src, index=False)
        # --plots (slow: matplotlib) has its own tests in test_outputs.py
        return (
            [src],
            {"-o": t / "flags.csv", "--json": t / "report.json"},
            lambda o: ["audit", src, "-o", o["-o"], "--json", o["--json"], "-q"],
        )

    def _draw(self, t):
        make_images(t / "imgs", ["a.png", "b.png"])
        src = t / "in.csv"
        pd.DataFrame({"image": ["a.png", "b.png"], "pitch": [1.0, 2], "yaw": [10.0, -20], "roll": [0.0, 5]}).to_csv(
            src, index=False
        )
        return (
            [src, t / "imgs" / "a.png", t / "imgs" / "b.png"],
            {"-o": t / "drawn", "--rejects": t / "rej.csv"},
            lambda o: ["draw", src, "-o", o["-o"], "--images", t / "imgs", "--rejects", o["--rejects"], "-q"],
        )

    def _view(self, t):
        make_images(t / "imgs", ["a.png", "b.png"])
        src = t / "in.csv"
        pd.DataFrame({"image": ["a.png", "b.png"], "pitch": [1.0, 2], "yaw": [10.0, -20], "roll": [0.0, 5]}).to_csv(
            src, index=False
        )
        return (
            [src, t / "imgs" / "a.png", t / "imgs" / "b.png"],
            {"-o": t / "page", "--rejects": t / "rej.csv"},
            lambda o: ["view", src, "-o", o["-o"], "--images", t / "imgs", "--rejects", o["--rejects"], "-q"],
        )

    def _augment(self, t):
        make_images(t / "imgs", ["a.png", "b.png"])
        src = t / "in.csv"
        pd.DataFrame({"image": ["a.png", "b.png"], "pitch": [1.0, 2], "yaw": [10.0, -20], "roll": [0.0, 5]}).to_csv(
            src, index=False
        )
        return (
            [src, t / "imgs" / "a.png"],
            {"-o": t / "aug.csv", "--rejects": t / "rej.csv", "--out-images": t / "augimgs"},
            lambda o: [
                "augment",
                src,
                "-o",
                o["-o"],
                "--image-size",
                "40x30",
                "--hflip",
                "--images",
                t / "imgs",
                "--out-images",
                o["--out-images"],
                "--rejects",
                o["--rejects"],
                "-q",
            ],
        )

    def _infer(self, t):
        code = t / "lp.py"
        shutil.copy(FIX / "lp300w.py", code)
        func = _first_function(code)
        return (
            [code],
            {"-o": t / "sys.toml", "--json": t / "report.json"},
            lambda o: ["infer", "--callable", f"{code}:{func}", "-o", o["-o"], "--json", o["--json"], "-q"],
        )

    def _evaluate(self, t):
        pred, gt = t / "pred.csv", t / "gt.csv"
        base = {
            "image": [f"i{k}.jpg" for k in range(4)],
            "pitch": [1.0, 2, 3, 4],
            "yaw": [10.0, -20, 30, 5],
            "roll": [0.0, 5, -5, 2],
        }
        pd.DataFrame(base).to_csv(gt, index=False)
        pd.DataFrame({**base, "yaw": [11.0, -21, 29, 5]}).to_csv(pred, index=False)
        return (
            [pred, gt],
            {"-o": t / "errors.csv", "--json": t / "report.json", "--rejects": t / "rej.csv"},
            lambda o: [
                "evaluate",
                pred,
                gt,
                "--pred-system",
                "300w_lp",
                "--gt-system",
                "300w_lp",
                "-o",
                o["-o"],
                "--json",
                o["--json"],
                "--rejects",
                o["--rejects"],
                "-q",
            ],
        )

    def _export(self, t):
        make_images(t / "img", ["f0.jpg", "f1.jpg"], size=(160, 120))
        rows = [
            {
                "image": f"img/f{i}.jpg",
                "sequence": "s0",
                "camera": "",
                "frame": i,
                "person_id": 0,
                "bbox_x": 10,
                "bbox_y": 20,
                "bbox_w": 40,
                "bbox_h": 50,
                "pitch": 5.0,
                "yaw": 20.0 * i - 10,
                "roll": 5.0,
            }
            for i in range(2)
        ]
        src = t / "labels.csv"
        pd.DataFrame(rows).to_csv(src, index=False)
        return (
            [src, t / "img" / "f0.jpg"],
            {"-o": t / "exported", "--rejects": t / "rej.csv"},
            lambda o: [
                "export",
                src,
                "-o",
                o["-o"],
                "--layout",
                "whenet",
                "--images",
                t,
                "--rejects",
                o["--rejects"],
                "-q",
            ],
        )


def _first_function(path: Path) -> str:
    import ast

    return next(
        n.name
        for n in ast.parse(path.read_text()).body
        if isinstance(n, ast.FunctionDef) and not n.name.startswith("_")
    )


COMMANDS = [
    "convert",
    "relabel-panoptic",
    "relabel-agora",
    "audit",
    "draw",
    "augment",
    "infer",
    "evaluate",
    "export",
    "view",
]
WRITING = COMMANDS  # every command that writes files (systems only prints)


@pytest.fixture
def case_factory(tmp_path):
    def make(name):
        return Case(name, tmp_path)

    return make


def children(pid: int, *, recursive: bool = True) -> set:
    """Every descendant process of ``pid`` (from /proc), children of children included unless not
    ``recursive``."""
    out = set()
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                out.update(int(x) for x in f.read().split())
    except OSError:
        return out
    if recursive:
        for c in list(out):
            out |= children(c)
    return out


def alive(pid: int) -> bool:
    """``pid`` exists and is neither a zombie nor dead."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False
