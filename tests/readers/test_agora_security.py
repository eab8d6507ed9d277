"""AGORA dataframes from untrusted files: restricted unpickling, Parquet, and validation at the door."""

from __future__ import annotations

import os
import pickle
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hpe_cli.datasets.agora import TO_PARQUET, load_dataframe, read_agora
from hpe_cli.errors import HpeError
from hpe_cli.pipelines.relabel.agora import Config, relabel_people

FIXTURE = Path(__file__).resolve().parents[1] / "data" / "agora" / "validation_0_withjv.pkl"


class Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_fixture_loads_restricted():
    df = load_dataframe(FIXTURE)
    ref = pd.read_pickle(FIXTURE)
    assert list(df.columns) == list(ref.columns) and df.shape == ref.shape
    assert df["imgPath"].tolist() == ref["imgPath"].tolist()
    for col in ("camR", "cam_j3d", "occlusion"):
        for a, b in zip(df[col], ref[col]):
            assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))


@pytest.mark.parametrize("name", ["evil.pkl", "evil.csv", "evil.parquet"])
def test_malicious_pickle_is_refused_whatever_its_name(tmp_path, name):
    marker = tmp_path / "pwned"
    path = tmp_path / name
    path.write_bytes(pickle.dumps(pd.DataFrame({"imgPath": ["a.png"], "x": [Evil(marker)]}), protocol=4))
    with pytest.raises(HpeError) as e:
        load_dataframe(path)
    msg = str(e.value)
    assert "refused" in msg and "posix.system" in msg or "os.system" in msg
    assert "--trust-pickle" in msg and "to_parquet" in msg
    assert not marker.exists()
    with pytest.raises(HpeError):  # the relabel entry point refuses it too
        read_agora(path)
    assert not marker.exists()


def test_parquet_conversion_one_liner_and_same_labels(tmp_path):
    out = tmp_path / "v.parquet"
    cmd = shlex.split(TO_PARQUET.replace("IN.pkl", str(FIXTURE)).replace("OUT.parquet", str(out)))
    subprocess.run(cmd[:1] + cmd[1:], check=True, executable=sys.executable if cmd[0] == "python" else None)
    a = relabel_people(read_agora(FIXTURE), Config(system="whenet"))
    b = relabel_people(read_agora(out), Config(system="whenet"))
    for k in a["table"]:
        if k == "source":  # the file's name
            continue
        x, y = np.asarray(a["table"][k]), np.asarray(b["table"][k])
        assert x.shape == y.shape and (
            np.array_equal(x, y) if x.dtype == object else np.allclose(x, y, equal_nan=True)
        ), k
    assert list(a["rejects"]["reason"]) == list(b["rejects"]["reason"])


def _broken(tmp_path, edit):
    df = pd.read_pickle(FIXTURE)
    edit(df)
    path = tmp_path / "broken.pkl"
    df.to_pickle(path, protocol=4)
    return path


@pytest.mark.parametrize(
    "edit, why",
    [
        (lambda df: df.at[0, "camR"].__setitem__(0, 2 * np.eye(3)), "camR not orthonormal"),
        (lambda df: df.at[0, "camR"].__setitem__(0, np.diag([1.0, 1.0, -1.0])), "camR determinant is not +1"),
        (lambda df: df.at[0, "camR"].__setitem__(0, np.full((3, 3), np.nan)), "camR not finite"),
        (lambda df: df.at[0, "camK"].__setitem__(0, np.zeros((3, 3))), "camK focal length not positive"),
        (lambda df: df.at[0, "camT"].__setitem__(0, np.array([np.inf, 0, 0])), "camT not finite"),
        (
            lambda df: df.at[0, "cam_j3d"].__setitem__(0, np.full_like(df.at[0, "cam_j3d"][0], 1e308)),
            "face joints infinite or |value| >= 1e6",
        ),
        (lambda df: df.__setitem__("imgPath", ["../../etc/passwd"] + list(df["imgPath"][1:])), "'..'"),
        (lambda df: df.__setitem__("imgPath", ["/etc/passwd"] + list(df["imgPath"][1:])), "absolute image path"),
        (lambda df: df.__setitem__("imgPath", ["a\x00b.png"] + list(df["imgPath"][1:])), "NUL"),
    ],
)
def test_bad_geometry_and_names_are_rejected_per_person(tmp_path, edit, why):
    path = _broken(tmp_path, edit)
    good = relabel_people(read_agora(FIXTURE), Config(system="whenet"))
    people = read_agora(path)
    res = relabel_people(people, Config(system="whenet"))
    rj = res["rejects"]
    hit = [(r, p, d) for r, p, s, d in zip(rj["row"], rj["person"], rj["reason"], rj["detail"]) if s == "bad input"]
    assert hit and all(r == 0 for r, _, _ in hit) and all(why in d for *_, d in hit)
    # every person is still accounted for; no unsafe name becomes an image value
    n = len(people)
    assert len(res["table"]["row"]) + len(rj["row"]) == n
    assert not any(".." in str(x) or str(x).startswith("/") for x in res["table"]["image"])
    assert len(res["table"]["row"]) <= len(good["table"]["row"])
