"""``--layout 6drepnet --trainer``: each trainer's own range rule, checked against its own code's arithmetic."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import hpe
from hpe_cli.io.export import get_layout

ANGLE = st.floats(-180, 180, allow_nan=False)


def hopenet_has_class(yaw, pitch, roll):
    """natanielruiz/deep-head-pose@f7bbb998 code/datasets.py:134-136 with 66 classes (train_hopenet.py:91)."""
    binned = np.digitize([yaw, pitch, roll], np.array(range(-99, 102, 3))) - 1
    return bool(((binned >= 0) & (binned < 66)).all())


def sixdrepnet_lists(pitch, yaw, roll):
    """thohemp/6DRepNet@464b2ba5 sixdrepnet/create_filename_list.py:53."""
    return abs(pitch) <= 99 and abs(yaw) <= 99 and abs(roll) <= 99


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(ANGLE, ANGLE, ANGLE), min_size=1, max_size=20))
def test_rules_match_the_trainers_code(angles):
    a = np.array(angles, dtype=np.float64)
    hop = get_layout("6drepnet", trainer="hopenet").label_reasons(a)
    six = get_layout("6drepnet", trainer="6drepnet").label_reasons(a)
    full = get_layout("6drepnet", trainer="6drepnet360").label_reasons(a)
    for k, (p, y, r) in enumerate(a.tolist()):
        assert (hop[k] == "") == hopenet_has_class(y, p, r)
        assert (six[k] == "") == sixdrepnet_lists(p, y, r)
        assert full[k] == ""


@pytest.mark.parametrize(
    "edge,hopenet,sixdrepnet",
    [(-99.0, True, True), (98.999, True, True), (99.0, False, True), (-99.001, False, False), (99.001, False, False)],
)
def test_edges(edge, hopenet, sixdrepnet):
    a = np.array([[0.0, edge, 0.0]])
    assert (get_layout("6drepnet", trainer="hopenet").label_reasons(a)[0] == "") == hopenet
    assert (get_layout("6drepnet").label_reasons(a)[0] == "") == sixdrepnet  # the .mat form's default
    assert get_layout("6drepnet", form="crops").label_reasons(a)[0] == ""  # DirectMHP's fork: full range


def test_trainer_only_for_6drepnet():
    with pytest.raises(ValueError, match="6drepnet only"):
        get_layout("hf", trainer="hopenet")
    with pytest.raises(ValueError, match="--trainer"):
        get_layout("6drepnet", trainer="whenet")


def test_cli_trainer_usage(tmp_path):

    (tmp_path / "t.csv").write_text("image,bbox_x,bbox_y,bbox_w,bbox_h,pitch,yaw,roll\n")
    r = hpe("export", tmp_path / "t.csv", "-o", tmp_path / "o", "--layout", "hf", "--trainer", "hopenet")
    assert r.exit_code == 2 and "--trainer applies to --layout 6drepnet only" in r.output
    r = hpe("export", "--help")
    assert "--trainer [hopenet|6drepnet|6drepnet360]" in r.output and "--trainer hopenet" in r.output
