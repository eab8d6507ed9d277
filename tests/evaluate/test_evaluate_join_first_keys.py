"""The streamed attempt's first look at two Parquet files (``lockstep.first_keys_differ``): key stems that differ
(told by their hashes) send the run to the key join at once, as ``_same_keys`` does; keys equal as written or on
their stems do not. Checked against Python's own comparison of the stems."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hpe_cli.io import open_table
from hpe_cli.pipelines.evaluate.lockstep import Unaligned, _same_keys, first_keys_differ
from hpe_cli.pipelines.evaluate.sides import SideReader, open_side
from hpe_cli.rotation.systems import get_system


def _stem(s):
    s = s.replace("\\", "/").split("/")[-1]
    return s[: s.rfind(".")] if "." in s else s


def _reader(path):
    table = open_table(path, 1000, with_lines=True)
    return SideReader(open_side(table, get_system("300w_lp"), "auto", "gt"), ["image"], None, False)


CASES = {
    "equal": (["a/x.png", "b/y.png"], ["a/x.png", "b/y.png"]),
    "stems equal": (["a/x.png", "b/y.png"], ["x.jpg", "c\\y"]),
    "stems differ": (["a/x.png", "b/y.png"], ["x.jpg", "z.jpg"]),
    "order differs": (["x", "y"], ["y", "x"]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_first_keys_differ_as_python_compares_the_stems(tmp_path, case):
    g, p = CASES[case]
    for name, keys in (("gt", g), ("pred", p)):
        n = len(keys)
        pq.write_table(pa.table({"image": keys, "pitch": np.zeros(n), "yaw": np.zeros(n), "roll": np.zeros(n)}),
                       tmp_path / f"{name}.parquet")  # fmt: skip
    want = g != p and [_stem(s) for s in g] != [_stem(s) for s in p]
    got = first_keys_differ(_reader(tmp_path / "gt.parquet"), _reader(tmp_path / "pred.parquet"), ["image"])
    assert got == want
    a, b = pa.table({"image": g}), pa.table({"image": p})
    ns = type("K", (), {})
    ga, pb = ns(), ns()
    ga.keys, pb.keys = a, b
    try:  # the full check the stream makes on each pair of chunks agrees
        _same_keys(ga, pb, ["image"], set())
        assert not want
    except Unaligned:
        assert want
