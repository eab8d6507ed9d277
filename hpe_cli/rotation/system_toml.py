"""Reading a rotation system from TOML: every key validated, hostile files refused in one line.

Every error reads ``FILE: key: expected X, got Y`` (:class:`SystemError_`). Beyond the
keys' meaning (:func:`system_from_dict`), a system file is bounded before anything
is built from it (:data:`LIMITS`): its size, its nesting depth, the length of
every array and string, and integers within TOML's 64-bit range, so a huge number,
a huge array or a deeply nested value is one line, quickly, never a hang or an
internal error.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from . import euler as _euler
from .system_def import (
    CANONICAL_TURNS,
    GIMBAL_TOL,
    MATRIX_LAYOUTS,
    ROLES,
    SELECTIONS,
    STORAGE_KINDS,
    RotationSystem,
    SystemError_,
    Turn,
)
from .system_text import format_value

#: bounds of a system file: bytes, nesting levels, items per array, characters per string
LIMITS = {"bytes": 1 << 20, "depth": 6, "items": 256, "chars": 20_000}
_INT64 = (-(1 << 63), (1 << 63) - 1)


_TOP_KEYS = {
    "name",
    "description",
    "notes",
    "source",
    "verified",
    "frame",
    "model_frame",
    "turns",
    "sequence",
    "storage",
    "order",
    "units",
    "ranges",
    "selection",
    "gimbal_tol",
    "storage_kind",
    "matrix_layout",
    "quaternion_order",
    "sixd_columns",
    "columns",
    "examples",
}
_TURN_KEYS = {"angle", "axis", "hand"}
_EXAMPLE_KEYS = {"angles", "canonical_angles", "matrix", "values", "note"}


def _closest(key, allowed):
    import difflib  # lazy: start-up

    m = difflib.get_close_matches(str(key), sorted(allowed), n=1)
    return f" (did you mean {m[0]!r}?)" if m else ""


def _expect(cond, where, what, got):
    if not cond:
        raise SystemError_(f"{where}: expected {what}, got {format_value(got)}")


def _number(v):
    """A TOML number that fits a float (a huge integer is no angle or matrix entry)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    return isinstance(v, float) or abs(v) <= 1 << 1023


def _matrix3(v, where):
    ok = (
        isinstance(v, (list, tuple))
        and len(v) == 3
        and all(isinstance(r, (list, tuple)) and len(r) == 3 and all(_number(x) for x in r) for r in v)
    )
    _expect(ok, where, "a 3x3 array of numbers", v)
    return tuple(tuple(float(x) for x in r) for r in v)


def system_from_dict(d: dict, source: str = "<dict>") -> RotationSystem:
    """Build a system from a parsed TOML/JSON mapping, validating every key.

    Every error reads ``"source: key: expected X, got Y"``: unknown keys
    (with a close match when there is one), wrong types, NaN or negative
    ``gimbal_tol``, NaN or inverted ranges, a frame that is not orthonormal,
    unknown storage/order/kind values, and worked examples that disagree with
    the definition.
    """
    _check_keys(d, source)
    kind = d.get("storage_kind", "angles")
    _expect(kind in STORAGE_KINDS, f"{source}: storage_kind", "one of " + ", ".join(STORAGE_KINDS), kind)
    frame = _matrix3(d["frame"], f"{source}: frame") if "frame" in d else ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0))
    model_frame = _matrix3(d["model_frame"], f"{source}: model_frame") if "model_frame" in d else None
    turns, angle_frame, sequence = _turns(d, source, kind)
    ranges = _ranges(d, source)
    g, order, six = _numbers(d, source)
    cols = d.get("columns", {})
    _expect(isinstance(cols, dict), f"{source}: columns", 'a [columns] table of name = "file column"', cols)
    raw_examples = _examples(d, source)
    _check_choices(d, source)
    try:
        system = RotationSystem(
            name=d["name"],
            description=str(d.get("description", "")),
            frame=frame,
            turns=turns,
            sequence=sequence,
            storage=str(d.get("storage", "active")),
            order=tuple(map(str, order)),
            units=str(d.get("units", "degrees")),
            ranges=ranges,
            selection=str(d.get("selection", "proper" if turns[0].axis == turns[2].axis else "tait_bryan")),
            gimbal_tol=float(g),
            notes=str(d.get("notes", "")),
            storage_kind=kind,
            matrix_layout=str(d.get("matrix_layout", "3x3")),
            quaternion_order=str(d.get("quaternion_order", "wxyz")),
            sixd_columns=tuple(six),
            model_frame=model_frame,
            columns=dict(cols),
            angle_frame=angle_frame,
            source=str(d.get("source", "")),
            verified=str(d.get("verified", "")),
            examples=tuple(dict(e) for e in raw_examples),
        )
    except SystemError_ as exc:
        msg = str(exc)
        prefix = f"system {d['name']!r}: "
        raise SystemError_(f"{source}: {msg.removeprefix(prefix)}") from None
    for n, e in enumerate(system.examples):
        check_example(system, e, f"{source}: examples[{n}]")
    return system


#: the keys whose values are strings
_STRING_KEYS = (
    "description",
    "notes",
    "source",
    "verified",
    "sequence",
    "storage",
    "units",
    "selection",
    "storage_kind",
    "matrix_layout",
    "quaternion_order",
)


def _check_keys(d, source: str) -> None:
    """A table of known top-level keys, a non-empty ``name``, strings where strings belong."""
    _expect(isinstance(d, dict), source, "a table of system keys", type(d).__name__)
    for key in d:
        if key not in _TOP_KEYS:
            raise SystemError_(
                f"{source}: {key}: unknown key{_closest(key, _TOP_KEYS)}; expected one of "
                f"{', '.join(sorted(_TOP_KEYS))}"
            )
    _expect(
        isinstance(d.get("name"), str) and d.get("name", "").strip() != "",
        f"{source}: name",
        "a non-empty string",
        d.get("name"),
    )
    for key in _STRING_KEYS:
        if key in d:
            _expect(isinstance(d[key], str), f"{source}: {key}", "a string", d[key])


def _turns(d, source: str, kind: str) -> tuple:
    """``(turns, angle_frame, sequence)``: the three ``[[turns]]`` (an Euler sequence, one per role), or the
    300W-LP canonical turns for a system that stores no angles and names none."""
    raw_turns = d.get("turns")
    if raw_turns is None:
        _expect(
            kind != "angles",
            f"{source}: turns",
            "three [[turns]] tables (angle, axis, hand) for a system that stores angles",
            None,
        )
        _expect(
            "sequence" not in d, f"{source}: sequence", "no sequence when there are no [[turns]]", d.get("sequence")
        )
        return CANONICAL_TURNS, "canonical", "intrinsic"
    _expect(
        isinstance(raw_turns, list) and len(raw_turns) == 3 and all(isinstance(t, dict) for t in raw_turns),
        f"{source}: turns",
        "three [[turns]] tables",
        raw_turns,
    )
    turns = [_turn(t, f"{source}: turns[{n}]") for n, t in enumerate(raw_turns)]
    roles = [t.angle for t in turns]
    _expect(sorted(roles) == sorted(ROLES), f"{source}: turns", "one turn each for pitch, yaw and roll", roles)
    try:
        _euler.parse_seq("".join(t.axis for t in turns))
    except ValueError:
        raise SystemError_(
            f"{source}: turns: expected axes forming an Euler sequence (no axis twice in a row), "
            f"got {''.join(t.axis for t in turns)}"
        ) from None
    return tuple(turns), "system", d.get("sequence", "intrinsic")


def _turn(t: dict, where: str) -> Turn:
    """One ``[[turns]]`` table (``where``: ``source: turns[n]``)."""
    for key in t:
        if key not in _TURN_KEYS:
            raise SystemError_(f"{where}.{key}: unknown key{_closest(key, _TURN_KEYS)}; expected angle, axis, hand")
    _expect(t.get("angle") in ROLES, f"{where}.angle", "pitch, yaw or roll", t.get("angle"))
    axis = t.get("axis")
    _expect(isinstance(axis, str) and axis.lower() in ("x", "y", "z"), f"{where}.axis", "x, y or z", axis)
    hand = t.get("hand", "right")
    _expect(hand in ("right", "left"), f"{where}.hand", "right or left", hand)
    return Turn(t["angle"], axis.lower(), hand)


def _ranges(d, source: str) -> dict:
    """``[ranges]``: role -> (low, high) in degrees, finite, low < high."""
    ranges = {}
    raw_ranges = d.get("ranges", {})
    _expect(isinstance(raw_ranges, dict), f"{source}: ranges", "a [ranges] table", raw_ranges)
    for k, v in raw_ranges.items():
        if k not in ROLES:
            raise SystemError_(f"{source}: ranges.{k}: unknown key{_closest(k, ROLES)}; expected pitch, yaw, roll")
        ok = isinstance(v, list) and len(v) == 2 and all(_number(x) for x in v)
        _expect(ok, f"{source}: ranges.{k}", "[low, high] in degrees", v)
        lo, hi = float(v[0]), float(v[1])
        _expect(np.isfinite(lo) and np.isfinite(hi), f"{source}: ranges.{k}", "finite numbers", v)
        _expect(lo < hi, f"{source}: ranges.{k}", "low < high", v)
        ranges[k] = (lo, hi)
    return ranges


def _numbers(d, source: str) -> tuple:
    """``(gimbal_tol, order, sixd_columns)``, each checked."""
    g = d.get("gimbal_tol", GIMBAL_TOL)
    _expect(
        _number(g) and np.isfinite(g) and 0 <= g < 1,
        f"{source}: gimbal_tol",
        "a number in [0, 1) (|cos| of the middle turn)",
        g,
    )
    order = d.get("order", list(ROLES))
    _expect(
        isinstance(order, list) and sorted(map(str, order)) == sorted(ROLES),
        f"{source}: order",
        "a permutation of pitch, yaw, roll",
        order,
    )
    six = d.get("sixd_columns", [0, 1])
    _expect(
        isinstance(six, list)
        and len(six) == 2
        and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 2 for c in six)
        and six[0] != six[1],
        f"{source}: sixd_columns",
        "two different matrix columns out of 0, 1, 2",
        six,
    )
    return g, order, six


def _examples(d, source: str) -> list:
    """``[[examples]]`` tables with known keys (their values are checked once the system is built)."""
    raw_examples = d.get("examples", [])
    _expect(
        isinstance(raw_examples, list) and all(isinstance(e, dict) for e in raw_examples),
        f"{source}: examples",
        "[[examples]] tables",
        raw_examples,
    )
    for n, e in enumerate(raw_examples):
        for key in e:
            if key not in _EXAMPLE_KEYS:
                raise SystemError_(
                    f"{source}: examples[{n}].{key}: unknown key{_closest(key, _EXAMPLE_KEYS)}; "
                    f"expected {', '.join(sorted(_EXAMPLE_KEYS))}"
                )
    return raw_examples


#: the string keys with a fixed set of values
_CHOICES = {
    "sequence": ("intrinsic", "extrinsic"),
    "storage": ("active", "transposed"),
    "units": ("degrees", "radians"),
    "selection": SELECTIONS,
    "matrix_layout": MATRIX_LAYOUTS,
    "quaternion_order": ("wxyz", "xyzw"),
}


def _check_choices(d, source: str) -> None:
    """Each of :data:`_CHOICES` present holds one of its values."""
    for key, allowed in _CHOICES.items():
        if key in d:
            _expect(d[key] in allowed, f"{source}: {key}", "one of " + ", ".join(allowed), d[key])


#: worked examples are written with 6 decimals
EXAMPLE_TOL = 2e-6


def example_matrix(system: RotationSystem, example: dict, where: str = "example") -> np.ndarray:
    """The stored matrix an example's angles build (``angles``: the system's; ``canonical_angles``: 300W-LP)."""
    if "angles" in example:
        a = example["angles"]
        _expect(
            isinstance(a, list) and len(a) == 3 and all(_number(x) for x in a),
            f"{where}.angles",
            "[pitch, yaw, roll] in degrees",
            a,
        )
        return system.from_angles(np.array([a], dtype=float))[0]
    if "canonical_angles" in example:
        a = example["canonical_angles"]
        _expect(
            isinstance(a, list) and len(a) == 3 and all(_number(x) for x in a),
            f"{where}.canonical_angles",
            "[pitch, yaw, roll] in degrees (300W-LP)",
            a,
        )
        A = RotationSystem("_canonical", "", ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0)), CANONICAL_TURNS).from_angles(
            np.array([a], dtype=float)
        )
        return system.from_canonical(A)[0]
    raise SystemError_(f"{where}: expected angles or canonical_angles, got neither")


def check_example(system: RotationSystem, example: dict, where: str) -> None:
    """Raise unless the example's matrix/values follow from its angles (within ``EXAMPLE_TOL``)."""
    R = example_matrix(system, example, where)
    if "matrix" in example:
        M = np.array(_matrix3(example["matrix"], f"{where}.matrix"))
        if not np.abs(M - R).max() <= EXAMPLE_TOL:
            raise SystemError_(
                f"{where}.matrix: expected {format_value(np.round(R, 6).tolist())} from the angles, got {format_value(M.tolist())}"
            )
    if "values" in example:
        v = example["values"]
        _expect(isinstance(v, list) and all(_number(x) for x in v), f"{where}.values", "a list of numbers", v)
        if system.storage_kind == "angles":
            raise SystemError_(
                f"{where}.values: expected no values for storage_kind angles (use angles), got {format_value(v)}"
            )
        want = system.matrix_to_values(R[None])[0]
        got = np.asarray(v, dtype=float)
        if got.shape != want.shape or not np.abs(got - want).max() <= EXAMPLE_TOL:
            raise SystemError_(
                f"{where}.values: expected {format_value(np.round(want, 6).tolist())} "
                f"({', '.join(system.value_columns)}) from the angles, got {format_value(v)}"
            )


def _where(path, keys) -> str:
    return f"{path}: {'.'.join(str(k) for k in keys) or 'file'}"


def _check_limits(data, path) -> None:
    """Raise unless every value is within :data:`LIMITS` (checked iteratively: no recursion)."""
    stack = [((), data, 0)]
    while stack:
        keys, value, depth = stack.pop()
        if depth > LIMITS["depth"]:
            raise SystemError_(f"{_where(path, keys)}: expected at most {LIMITS['depth']} levels of nesting, got more")
        if isinstance(value, dict):
            stack.extend((keys + (k,), v, depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            if len(value) > LIMITS["items"]:
                raise SystemError_(f"{_where(path, keys)}: expected at most {LIMITS['items']} items, got {len(value)}")
            stack.extend((keys + (n,), v, depth + 1) for n, v in enumerate(value))
        elif isinstance(value, str) and len(value) > LIMITS["chars"]:
            raise SystemError_(f"{_where(path, keys)}: expected at most {LIMITS['chars']} characters, got {len(value)}")
        elif isinstance(value, int) and not isinstance(value, bool) and not _INT64[0] <= value <= _INT64[1]:
            raise SystemError_(
                f"{_where(path, keys)}: expected a 64-bit integer (TOML), got a {len(str(abs(value)))}-digit number"
            )


def _line_key(line: str, table: str):
    """``(key, table)`` after a top-level line: ``key = ...`` names ``table.key``, ``[table]`` starts a table."""

    m = re.match(r"\s*\[+\s*([A-Za-z0-9_.\-]+)\s*\]+", line)
    if m:
        return m.group(1), m.group(1)
    m = re.match(r"\s*([A-Za-z0-9_.\-]+)\s*=", line)
    if m:
        return (f"{table}.{m.group(1)}" if table else m.group(1)), table
    return None, table


def _key_at(text: str, offset: int) -> str:
    """The key whose value holds ``offset`` of a TOML text (a rough scan, for messages only)."""
    key, table = "file", ""
    for line in text[:offset].splitlines():
        found, table = _line_key(line, table)
        key = found or key
    return key


def _deepest_key(text: str) -> str:
    """The key whose value nests deepest (a rough scan, for the message of a file too deep to parse)."""
    depth, best, key, table, in_str = 0, (-1, "file"), "file", "", None
    for line in text.splitlines():
        if depth == 0:
            found, table = _line_key(line, table)
            key = found or key
        for ch in line:
            if in_str:
                in_str = None if ch == in_str else in_str
            elif ch in "\"'":
                in_str = ch
            elif ch in "[{":
                depth += 1
                best = max(best, (depth, key))
            elif ch in "]}":
                depth = max(0, depth - 1)
        in_str = None
    return best[1]


def read_system_file(path) -> RotationSystem:
    """A system from a TOML file, bounded (:data:`LIMITS`) and validated (:func:`system_from_dict`)."""
    import tomllib  # lazy: start-up

    path = Path(path)
    if path.is_dir():
        raise SystemError_(f"{path}: expected a .toml file, got a folder")
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise SystemError_(f"{path}: no such system file") from None
    if size > LIMITS["bytes"]:
        raise SystemError_(f"{path}: file: expected a system file of at most {LIMITS['bytes']} bytes, got {size}")
    text = ""
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text)
    except FileNotFoundError:
        raise SystemError_(f"{path}: no such system file") from None
    except RecursionError:
        raise SystemError_(
            f"{path}: {_deepest_key(text)}: expected at most {LIMITS['depth']} levels of nesting, got too many to parse"
        ) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, ValueError) as exc:  # ValueError: a > 4300-digit int
        big = re.search(r"\d{4300,}", text) if not isinstance(exc, tomllib.TOMLDecodeError) else None
        if big is not None:
            raise SystemError_(
                f"{path}: {_key_at(text, big.start())}: expected a 64-bit integer (TOML), got a "
                f"{len(big.group())}-digit number"
            ) from None
        raise SystemError_(f"{path}: not valid TOML ({' '.join(str(exc).split())[:200]})") from None
    _check_limits(data, path)
    return system_from_dict(data, str(path))
