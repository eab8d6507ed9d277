"""WHENet's 58-point reference head, its landmark pairs and the helmet constants.

The numbers live in ``hpe_cli/data/whenet_reference_head.json`` (see the
``README.md`` there for their source). The head is in the canonical 300W-LP
frame (x: subject's left, y: up, z: out of the face) in WHENet's own units,
about 1 unit per cm: the nose tip (point 52) is at (0, 0, 6.76).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from importlib.resources import files

import numpy as np

PRESETS = ("whenet", "directmhp")


@lru_cache(maxsize=1)
def _data() -> dict:

    return json.loads((files("hpe_cli.data") / "whenet_reference_head.json").read_text(encoding="utf-8"))


def reference_head() -> np.ndarray:
    """The 58 reference points, shape (58, 3), float64 (a fresh copy)."""
    return np.asarray(_data()["points"], dtype=np.float64)


def panoptic_pairs() -> tuple[np.ndarray, np.ndarray]:
    """WHENet's 14 pairs: (face70 indices, reference-head indices)."""
    p = _data()["panoptic_face70_pairs"]
    return np.asarray(p["face70"], dtype=np.intp), np.asarray(p["head"], dtype=np.intp)


def agora_pairs() -> tuple[np.ndarray, np.ndarray]:
    """DirectMHP's 13 AGORA pairs: (indices into the 51 face joints, reference-head indices)."""
    p = _data()["agora_face51_pairs"]
    return np.asarray(p["face51"], dtype=np.intp), np.asarray(p["head"], dtype=np.intp)


def confidence_min() -> float:
    """A landmark pair is used when its confidence is strictly above this (0.1)."""
    return float(_data()["confidence_min_exclusive"])


def min_pairs() -> int:
    """WHENet fits a face only with at least this many confident pairs (7)."""
    return int(_data()["min_pairs"])


@dataclass(frozen=True)
class HelmetPreset:
    """The helmet sphere and the box rule of one tool (SPEC §6).

    Attributes
    ----------
    name : {"whenet", "directmhp"}
    radius : float
        Sphere radius in reference-head units (22 or 18).
    offset : tuple of 3 floats
        Sphere centre in reference-head units, (0, 5, -5).
    max_aspect : float
        Longest side over shortest side must be ``<= max_aspect`` (WHENet, 2)
        or ``< max_aspect`` (DirectMHP, 1.5; ``aspect_inclusive`` False).
    aspect_inclusive : bool
    max_side_fraction : float
        The box needs ``w < max_side_fraction * width`` and, when
        ``check_height``, ``h < max_side_fraction * height``. DirectMHP: 0.7 on
        both sides; WHENet: 1.0 on the width only.
    check_height : bool
    """

    name: str
    radius: float
    offset: tuple
    max_aspect: float
    aspect_inclusive: bool
    max_side_fraction: float
    check_height: bool

    def describe(self) -> str:
        op = "<=" if self.aspect_inclusive else "<"
        side = (
            f"each side < {self.max_side_fraction:g} x image"
            if self.check_height
            else f"width < {self.max_side_fraction:g} x image width"
        )
        return f"radius {self.radius:g}, aspect {op} {self.max_aspect:g}, {side}"


def helmet_preset(name: str = "whenet") -> HelmetPreset:
    """The :class:`HelmetPreset` called ``name`` (``whenet`` or ``directmhp``)."""
    if isinstance(name, HelmetPreset):
        return name
    h = _data()["helmet"]
    if name not in h:
        raise ValueError(f"expected a helmet preset in {tuple(h)}, got {name!r}")
    p = h[name]
    if "max_aspect" in p:
        aspect, inclusive = float(p["max_aspect"]), True
    else:
        aspect, inclusive = float(p["max_aspect_exclusive"]), False
    return HelmetPreset(
        name=name,
        radius=float(p["radius"]),
        offset=tuple(float(v) for v in p["offset"]),
        max_aspect=aspect,
        aspect_inclusive=inclusive,
        max_side_fraction=float(p.get("max_side_fraction", 1.0)),
        check_height="max_side_fraction" in p,
    )
