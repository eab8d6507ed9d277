"""Issue 9.11: user TOML systems are validated completely; every error is 'file: key: expected X, got Y'."""

import pytest

from hpe_cli.rotation import SystemError_, get_system, load_system

TURNS = "".join(
    f'\n[[turns]]\nangle = "{r}"\naxis = "{a}"\nhand = "right"\n'
    for r, a in [("yaw", "z"), ("pitch", "y"), ("roll", "x")]
)


def write(tmp_path, text, name="user.toml"):
    f = tmp_path / name
    f.write_text(text)
    return f


@pytest.mark.parametrize(
    "body,match",
    [
        ("gimbal_tol = -1e-4", r"gimbal_tol: expected a number in \[0, 1\).*got -0.0001"),
        ("gimbal_tol = nan", r"gimbal_tol: expected .* got NaN"),
        ('gimbal_tol = "small"', r"gimbal_tol: expected .* got \"small\""),
        ("[ranges]\nyaw = [90, -90]", r"ranges.yaw: expected low < high, got \[90, -90\]"),
        ("[ranges]\nyaw = [nan, 90]", r"ranges.yaw: expected finite numbers"),
        ("[ranges]\nyaw = [-90]", r"ranges.yaw: expected \[low, high\]"),
        ("[ranges]\nyw = [-90, 90]", r"ranges.yw: unknown key \(did you mean 'yaw'\?\)"),
        ("gimbal_tolerance = 1e-4", r"gimbal_tolerance: unknown key \(did you mean 'gimbal_tol'\?\)"),
        ("frame = [[1, 0, 0], [0, 1, 0], [0, 0.5, 1]]", r"frame: expected an orthonormal 3x3 matrix"),
        ("frame = [[1, 0, 0], [0, 1, 0]]", r"frame: expected a 3x3 array of numbers"),
        ('storage = "inverse"', r"storage: expected one of active, transposed, got \"inverse\""),
        ('storage_kind = "euler"', r"storage_kind: expected one of angles, matrix, rotvec, quaternion, 6d"),
        ('order = ["pitch", "yaw", "yaw"]', r"order: expected a permutation of pitch, yaw, roll"),
        ('units = "grad"', r"units: expected one of degrees, radians"),
        ('sequence = "both"', r"sequence: expected one of intrinsic, extrinsic"),
        ('quaternion_order = "wzyx"', r"quaternion_order: expected one of wxyz, xyzw"),
        ("sixd_columns = [1, 1]", r"sixd_columns: expected two different matrix columns"),
        ('[columns]\npich = "P"', r"columns.pich: expected a key among pitch, yaw, roll"),
        (
            "[[examples]]\nangles = [10, 20, 30]\nmatrix = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]",
            r"examples\[0\].matrix: expected \[\[.*from the angles, got",
        ),
    ],
)
def test_bad_key_is_named(tmp_path, body, match):
    f = write(
        tmp_path,
        'name = "mine"\n' + body + "\n" + TURNS
        if not body.startswith("[")
        else 'name = "mine"\n' + TURNS + "\n" + body + "\n",
    )
    with pytest.raises(SystemError_, match=match) as exc:
        load_system(f)
    assert str(exc.value).startswith(str(f) + ": ")


def test_bad_turns(tmp_path):
    f = write(tmp_path, 'name = "m"\n[[turns]]\nangle = "pitch"\naxis = "q"\n')
    with pytest.raises(SystemError_, match=r"turns: expected three"):
        load_system(f)
    f = write(tmp_path, 'name = "m"\n' + TURNS.replace('axis = "y"', 'axis = "w"'))
    with pytest.raises(SystemError_, match=r"turns\[1\].axis: expected x, y or z, got \"w\""):
        load_system(f)
    f = write(tmp_path, 'name = "m"\n' + TURNS.replace('hand = "right"', 'handed = "right"', 1))
    with pytest.raises(SystemError_, match=r"turns\[0\].handed: unknown key"):
        load_system(f)
    f = write(tmp_path, 'name = "m"\n')
    with pytest.raises(SystemError_, match=r"turns: expected three \[\[turns\]\] tables"):
        load_system(f)


def test_builtin_name_with_other_definition(tmp_path):
    s = get_system("300w_lp")
    same = write(tmp_path, s.to_toml(), "same.toml")
    assert load_system(same).definition() == s.definition()
    other = write(tmp_path, s.to_toml().replace('hand = "left"', 'hand = "right"', 1), "other.toml")
    with pytest.raises(SystemError_, match=r"other.toml: name: expected a name that is not a built-in.*got '300w_lp'"):
        load_system(other)


def test_improper_model_frame_mismatch(tmp_path):
    f = write(tmp_path, 'name = "m"\nstorage_kind = "matrix"\nframe = [[1, 0, 0], [0, -1, 0], [0, 0, 1]]\n')
    assert not load_system(f).proper_frame  # an improper frame alone is fine (B A B^T is a rotation)
    f = write(
        tmp_path,
        'name = "m"\nstorage_kind = "matrix"\nframe = [[1, 0, 0], [0, -1, 0], [0, 0, 1]]\n'
        "model_frame = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n",
    )
    with pytest.raises(SystemError_, match=r"model_frame: expected det\(frame\) \* det\(model_frame\) = \+1"):
        load_system(f)


def test_every_builtin_round_trips_through_toml(tmp_path):
    from hpe_cli.rotation import builtin_systems

    for name, s in builtin_systems().items():
        f = write(tmp_path, s.to_toml(), f"{name}.toml")
        assert load_system(f).definition() == s.definition(), name


def test_docs_example_system_loads():
    import re
    import tomllib
    from pathlib import Path

    from hpe_cli.rotation import system_from_dict

    text = (Path(__file__).resolve().parents[2] / "docs" / "commands" / "systems.md").read_text()
    block = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    s = system_from_dict(tomllib.loads(block), "docs/commands/systems.md")
    assert s.storage_kind == "quaternion" and s.value_columns == ["q1", "q2", "q3", "q0"]
