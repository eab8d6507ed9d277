"""Legacy decoders: what published code prints for a rotation, reproduced exactly.

These are not rotation systems: each is a function some paper used to turn a
matrix into three numbers, with its own shortcuts. ``hpe convert --decoder``
writes their output beside the exact angles and ``hpe audit --decoder`` says
how far they are from the rotation. Every decoder takes the canonical 300W-LP
matrix ``A`` (the active matrix all three codes feed it: 3DDFA's and
SynergyNet's ``P2sRt`` rotation, DirectMHP's ``rotate_zyx``) and returns
angles in role order ``(pitch, yaw, roll)``, degrees.

- ``synergynet``: SynergyNet ``matrix2angle_corr`` (choyingw/SynergyNet
  ``utils/inference.py``): ``yaw = asin(R20)``, ``pitch = atan2(R12, R22)``,
  ``roll = atan2(R01, R00)`` (each over ``cos yaw``), lock only when ``R20``
  is exactly +-1. It mixes two systems' index patterns (SPEC section 3):
  pitch and roll are the 300W-LP angles, yaw is 3DDFA's; measured against ``300w_lp``.
- ``3ddfa_v2``: 3DDFA_V2 ``matrix2angle`` (cleardusk/3DDFA_V2 ``utils/pose.py``):
  the ``3ddfa_v2`` system's split, but with ``|R20| > 0.998`` (about 86.4 deg of
  yaw) forced to roll = 0, yaw = +-90.
- ``directmhp``: DirectMHP's full-range decoder (hnuzhy/DirectMHP
  ``exps/CMU/hpe_utils.py``): ``inverse_rotate_zyx`` (both solutions, lock
  when ``|M02| > 0.9999999``), degrees, then ``select_euler`` (the first
  solution with ``|pitch| < 90`` and ``|roll| < 90``; yaw wrapped only above
  180; rows with neither are returned as -999 and ``ok = False``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..registry import Registry
from .convert import canonical_to_labels
from .distances import geodesic_deg
from .euler import wrap_180
from .systems import get_system

_DEG = 180.0 / np.pi


@dataclass(frozen=True)
class Decoder:
    name: str
    source: str
    reference: str  # the exact system whose angles the decoder means to print
    description: str
    func: Callable = None  # canonical matrices (N, 3, 3) -> (pyr (N, 3) degrees, ok (N,))


#: name -> :class:`Decoder` (``hpe convert --decoder NAME``, ``hpe audit --decoder NAME``)
DECODERS = Registry("decoder")


def register_decoder(name: str, source: str, reference: str, description: str) -> Callable:
    """Decorator: register ``func(A) -> (pyr, ok)`` as the decoder ``name`` in :data:`DECODERS`.

    ``A`` is ``(N, 3, 3)`` canonical 300W-LP matrices; ``pyr`` the ``(N, 3)`` angles the published code prints,
    role order (pitch, yaw, roll), degrees; ``ok`` the rows it produced numbers for. ``source`` names the code
    reproduced, ``reference`` the exact system whose angles the decoder means to print.
    """

    def add(func: Callable) -> Callable:
        DECODERS.register(name, Decoder(name, source, reference, description, func))
        return func

    return add


@register_decoder(
    "synergynet",
    "choyingw/SynergyNet utils/inference.py (matrix2angle_corr)",
    "300w_lp",
    "SynergyNet matrix2angle_corr: yaw = asin(R20) with pitch/roll from another system's indices",
)
def _synergynet(A):
    r20 = A[:, 2, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.arcsin(r20)  # NaN where |R20| > 1, where Python's math.asin raises
        c = np.cos(x)
        y = np.arctan2(A[:, 1, 2] / c, A[:, 2, 2] / c)
        z = np.arctan2(A[:, 0, 1] / c, A[:, 0, 0] / c)
    lock_neg, lock_pos = r20 == -1.0, r20 == 1.0
    # else-branch of the published code: z = 0; R20 == -1 -> x = pi/2, y = atan2(R01, R02);
    # otherwise (R20 == +1) x = -pi/2, y = atan2(-R01, -R02)
    x = np.where(lock_neg, np.pi / 2, np.where(lock_pos, -np.pi / 2, x))
    y = np.where(
        lock_neg, np.arctan2(A[:, 0, 1], A[:, 0, 2]), np.where(lock_pos, np.arctan2(-A[:, 0, 1], -A[:, 0, 2]), y)
    )
    z = np.where(lock_neg | lock_pos, 0.0, z)
    yaw, pitch, roll = x * _DEG, y * _DEG, z * _DEG
    pyr = np.stack([pitch, yaw, roll], -1)
    return pyr, np.isfinite(pyr).all(-1)


@register_decoder(
    "3ddfa_v2",
    "cleardusk/3DDFA_V2 utils/pose.py (matrix2angle)",
    "3ddfa_v2",
    "3DDFA_V2 matrix2angle: the 3ddfa_v2 split, roll forced to 0 when |R20| > 0.998",
)
def _tddfa_v2(A):
    r20 = A[:, 2, 0]
    hi, lo = r20 > 0.998, r20 < -0.998
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.arcsin(np.where(hi | lo, 0.0, r20))
        c = np.cos(x)
        y = np.arctan2(A[:, 2, 1] / c, A[:, 2, 2] / c)
        z = np.arctan2(A[:, 1, 0] / c, A[:, 0, 0] / c)
    x = np.where(hi, np.pi / 2, np.where(lo, -np.pi / 2, x))
    y = np.where(hi, np.arctan2(-A[:, 0, 1], -A[:, 0, 2]), np.where(lo, np.arctan2(A[:, 0, 1], A[:, 0, 2]), y))
    z = np.where(hi | lo, 0.0, z)
    pyr = np.stack([y * _DEG, x * _DEG, z * _DEG], -1)
    return pyr, np.isfinite(pyr).all(-1)


@register_decoder(
    "directmhp",
    "hnuzhy/DirectMHP exps/CMU/hpe_utils.py (inverse_rotate_zyx, select_euler)",
    "whenet",
    "DirectMHP full-range decoder: both solutions, the first with |pitch|, |roll| < 90; lock at |M02| > 0.9999999",
)
def _directmhp(M):
    m02 = M[:, 0, 2]
    lock = np.abs(m02) > 0.9999999
    with np.errstate(invalid="ignore", divide="ignore"):
        y0 = np.arcsin(-m02)
        y1 = np.pi - y0
        cy0, cy1 = np.cos(y0), np.cos(y1)
        x0 = np.arctan2(M[:, 1, 2] / cy0, M[:, 2, 2] / cy0)
        x1 = np.arctan2(M[:, 1, 2] / cy1, M[:, 2, 2] / cy1)
        z0 = np.arctan2(M[:, 0, 1] / cy0, M[:, 0, 0] / cy0)
        z1 = np.arctan2(M[:, 0, 1] / cy1, M[:, 0, 0] / cy1)
    # gimbal branch: z = 0; M02 > 0 -> y = -pi/2, x = atan2(-M10, -M20); else y = pi/2, x = atan2(M10, M20)
    pos = m02 > 0
    yl = np.where(pos, -np.pi / 2, np.pi / 2)
    xl = np.where(pos, np.arctan2(-M[:, 1, 0], -M[:, 2, 0]), np.arctan2(M[:, 1, 0], M[:, 2, 0]))
    x0, y0, z0 = np.where(lock, xl, x0), np.where(lock, yl, y0), np.where(lock, 0.0, z0)
    x1, y1, z1 = np.where(lock, xl, x1), np.where(lock, yl, y1), np.where(lock, 0.0, z1)
    # np.rad2deg of both sets, then select_euler(two_sets): sets are (pitch, yaw, roll)
    p, yw, r = x0 * _DEG, y0 * _DEG, z0 * _DEG
    p2, yw2, r2 = x1 * _DEG, y1 * _DEG, z1 * _DEG
    yw = np.where(yw > 180.0, yw - 360.0, yw)
    yw2 = np.where(yw2 > 180.0, yw2 - 360.0, yw2)
    first = (np.abs(r) < 90) & (np.abs(p) < 90)
    second = ~first & (np.abs(r2) < 90) & (np.abs(p2) < 90)
    ok = first | second
    pyr = np.where(first[:, None], np.stack([p, yw, r], -1), np.stack([p2, yw2, r2], -1))
    pyr[~ok] = -999.0
    return pyr, ok


def get_decoder(name: str) -> Decoder:
    """The decoder called ``name``; ``ValueError`` "expected a decoder among ..., got 'x'" otherwise."""
    return DECODERS.get(name)


def decode(name: str, A):
    """What decoder ``name`` prints for canonical matrices ``A`` ``(N, 3, 3)``.

    Returns ``(pyr, ok)``: ``(N, 3)`` angles in role order (pitch, yaw, roll),
    degrees, and a mask of rows the decoder produced numbers for.
    """
    func = get_decoder(name).func
    A = np.asarray(A, dtype=np.float64).reshape(-1, 3, 3)
    return func(A)


def decoder_columns(name: str, A) -> dict:
    """``decoder_pitch, decoder_yaw, decoder_roll, decoder_ok`` columns for ``A``."""
    pyr, ok = decode(name, A)
    return {
        "decoder_pitch": pyr[:, 0],
        "decoder_yaw": pyr[:, 1],
        "decoder_roll": pyr[:, 2],
        "decoder_ok": ok.astype(bool),
    }


def decoder_errors(name: str, A):
    """Per-row differences between a decoder's output and the exact rotation.

    Returns a dict of arrays: ``geodesic_deg`` (angle between ``A`` and the
    rotation the printed angles denote in the decoder's reference system),
    ``d_pitch, d_yaw, d_roll`` (wrapped differences from the reference system's
    exact primary angles, degrees) and ``ok``.
    """

    A = np.asarray(A, dtype=np.float64).reshape(-1, 3, 3)
    dec = get_decoder(name)
    ref = get_system(dec.reference)
    pyr, ok = decode(name, A)
    exact = canonical_to_labels(A, ref).primary
    safe = np.where(ok[:, None], pyr, 0.0)
    rebuilt = ref.to_canonical(ref.from_angles(safe))
    geo = np.where(ok, geodesic_deg(rebuilt, A), np.nan)
    d = np.where(ok[:, None], np.abs(wrap_180(safe - exact)), np.nan)
    return {"geodesic_deg": geo, "d_pitch": d[:, 0], "d_yaw": d[:, 1], "d_roll": d[:, 2], "ok": ok}


def summarise_errors(errs: dict) -> dict:
    """max/mean of :func:`decoder_errors` over usable rows, plus row counts."""
    ok = errs["ok"]
    out = {"rows": int(ok.size), "decoded": int(ok.sum()), "not_decoded": int((~ok).sum())}
    for k in ("geodesic_deg", "d_pitch", "d_yaw", "d_roll"):
        v = errs[k][ok]
        out[k] = {"max": float(v.max()) if v.size else 0.0, "mean": float(v.mean()) if v.size else 0.0}
    out["rows_off_by_more_than_0.01deg"] = int((errs["geodesic_deg"][ok] > 0.01).sum())
    return out


class DecoderTally:
    """Streaming max/mean of :func:`decoder_errors` over batches (flat memory).

    ``add(A)`` takes canonical matrices (rows with non-finite entries are
    skipped); ``result()`` gives the same dict as :func:`summarise_errors`
    plus the decoder's name, source and reference system.
    """

    KEYS = ("geodesic_deg", "d_pitch", "d_yaw", "d_roll")

    def __init__(self, name: str):
        self.decoder = get_decoder(name)
        self.rows = self.decoded = self.off = 0
        self.max = dict.fromkeys(self.KEYS, 0.0)
        self.sum = dict.fromkeys(self.KEYS, 0.0)

    def add(self, A) -> None:
        A = np.asarray(A, dtype=np.float64).reshape(-1, 3, 3)
        A = A[np.isfinite(A).all(axis=(1, 2))]
        if not len(A):
            return
        e = decoder_errors(self.decoder.name, A)
        ok = e["ok"]
        self.rows += len(A)
        self.decoded += int(ok.sum())
        self.off += int((e["geodesic_deg"][ok] > 0.01).sum())
        for k in self.KEYS:
            v = e[k][ok]
            if v.size:
                self.max[k] = max(self.max[k], float(v.max()))
                self.sum[k] += float(v.sum())

    def result(self) -> dict:
        d = self.decoder
        out = {
            "decoder": d.name,
            "source": d.source,
            "reference_system": d.reference,
            "rows": self.rows,
            "decoded": self.decoded,
            "not_decoded": self.rows - self.decoded,
            "rows_off_by_more_than_0.01deg": self.off,
            "note": "geodesic_deg: angle between the rotation and the one the printed angles denote in the "
            "reference system; d_*: differences from the reference system's exact angles (degrees)",
        }
        for k in self.KEYS:
            out[k] = {"max": self.max[k], "mean": self.sum[k] / self.decoded if self.decoded else 0.0}
        return out
