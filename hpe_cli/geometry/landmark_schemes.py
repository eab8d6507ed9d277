"""Left/right index permutations of the common 2-D face landmark schemes.

A mirror of the image turns the subject's left eye into a right eye. After the
coordinates are mirrored, the landmarks must be re-indexed with the scheme's
left/right permutation ``perm`` (``new[i] = mirrored[perm[i]]``), so that
index 36 of iBUG-68 is still the outer corner of the subject's right eye.
Every permutation here is an involution (``perm[perm] == arange``).

Schemes
-------
``ibug68``
    The 68 iBUG / 300-W points (0-based): jaw 0-16, brows 17-26, nose bridge
    27-30, nostrils 31-35, eyes 36-47, outer lips 48-59, inner lips 60-67.
``face70``
    CMU Panoptic's ``face70``: iBUG-68, then the two pupils 68 and 69, which
    swap under a mirror.
``aflw21``
    The 21 AFLW points (0-based; AFLW2000-3D ``pt2d``): brows 0-5, eyes 6-11
    (corner, centre, corner), ears 12 and 16, nose 13-15, mouth 17-19, chin 20.
"""

from __future__ import annotations

import numpy as np


def _from_pairs(n: int, pairs) -> np.ndarray:
    perm = np.arange(n)
    for a, b in pairs:
        perm[a], perm[b] = b, a
    return perm


_IBUG68_PAIRS = (
    [(i, 16 - i) for i in range(8)]  # jaw; 8 is the chin
    + [(17 + i, 26 - i) for i in range(5)]  # brows
    + [(31, 35), (32, 34)]  # nostrils; 27-30 and 33 on the midline
    + [(36, 45), (37, 44), (38, 43), (39, 42), (40, 47), (41, 46)]  # eyes
    + [(48, 54), (49, 53), (50, 52), (55, 59), (56, 58)]  # outer lips; 51, 57 on the midline
    + [(60, 64), (61, 63), (65, 67)]  # inner lips; 62, 66 on the midline
)
_AFLW21_PAIRS = [(0, 5), (1, 4), (2, 3), (6, 11), (7, 10), (8, 9), (12, 16), (13, 15), (17, 19)]

#: scheme name -> left/right permutation (read-only int arrays)
SCHEMES = {
    "ibug68": _from_pairs(68, _IBUG68_PAIRS),
    "face70": _from_pairs(70, _IBUG68_PAIRS + [(68, 69)]),
    "aflw21": _from_pairs(21, _AFLW21_PAIRS),
}
for _p in SCHEMES.values():
    _p.setflags(write=False)

SCHEME_NAMES = tuple(SCHEMES)


def scheme_for_count(n: int) -> str | None:
    """The built-in scheme with ``n`` landmarks, or None (68, 70 and 21 are distinct)."""
    return next((name for name, p in SCHEMES.items() if p.size == n), None)


def check_permutation(perm, n: int | None = None) -> np.ndarray:
    """Validate a left/right permutation.

    Parameters
    ----------
    perm : array_like of int, shape (L,)
    n : int, optional
        Expected number of landmarks.

    Returns
    -------
    ndarray of intp, shape (L,)

    Raises
    ------
    ValueError
        If ``perm`` is not a permutation of ``0..L-1``, is not an involution, or
        does not have ``n`` entries.
    """
    p = np.asarray(perm)
    if p.ndim != 1 or not np.issubdtype(p.dtype, np.integer):
        raise ValueError(f"expected a 1-D integer permutation, got shape {p.shape} dtype {p.dtype}")
    p = p.astype(np.intp)
    if n is not None and p.size != n:
        raise ValueError(f"expected a permutation of {n} landmarks, got {p.size}")
    if not np.array_equal(np.sort(p), np.arange(p.size)):
        raise ValueError(f"expected a permutation of 0..{p.size - 1}, got repeated or missing indices")
    if not np.array_equal(p[p], np.arange(p.size)):
        raise ValueError("expected a left/right permutation that is its own inverse (perm[perm] == arange)")
    return p


def flip_permutation(scheme, n: int | None = None) -> np.ndarray:
    """The left/right permutation of ``scheme``.

    Parameters
    ----------
    scheme : {"ibug68", "face70", "aflw21"} or array_like of int
        A built-in name or an explicit permutation.
    n : int, optional
        Number of landmarks the caller has; checked against the scheme.

    Returns
    -------
    ndarray of intp, shape (L,)
        ``new[i] = mirrored[perm[i]]``.
    """
    if isinstance(scheme, str):
        if scheme not in SCHEMES:
            raise ValueError(f"expected a landmark scheme in {', '.join(SCHEME_NAMES)}, got {scheme!r}")
        p = SCHEMES[scheme]
        if n is not None and p.size != n:
            raise ValueError(f"scheme {scheme} has {p.size} landmarks, got {n}")
        return p
    return check_permutation(scheme, n)
