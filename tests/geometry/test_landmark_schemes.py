"""Left/right landmark permutations, checked against 3-D and real 2-D landmark data."""

from pathlib import Path

import numpy as np
import pytest

from hpe_cli.geometry.landmark_schemes import SCHEMES, check_permutation, flip_permutation, scheme_for_count

DATA = Path(__file__).resolve().parents[2] / "hpe_cli" / "data"


@pytest.mark.parametrize("name", sorted(SCHEMES))
def test_every_scheme_is_an_involution(name):
    p = SCHEMES[name]
    assert np.array_equal(np.sort(p), np.arange(p.size))
    assert np.array_equal(p[p], np.arange(p.size))
    assert not p.flags.writeable
    assert scheme_for_count(p.size) == name


def test_face70_is_ibug68_plus_swapped_pupils():
    assert np.array_equal(SCHEMES["face70"][:68], SCHEMES["ibug68"])
    assert SCHEMES["face70"][68] == 69 and SCHEMES["face70"][69] == 68


def test_ibug68_midline_points_are_fixed():
    # chin, nose bridge and tip, nostril centre, lip centres (the iBUG-68 layout)
    midline = [8, 27, 28, 29, 30, 33, 51, 57, 62, 66]
    p = SCHEMES["ibug68"]
    assert np.array_equal(np.flatnonzero(p == np.arange(68)), midline)
    assert p[36] == 45 and p[39] == 42 and p[48] == 54 and p[0] == 16


def test_ibug68_mirrors_the_3d_reference_head():
    """The 68-point mean 3-D face is nearly left/right symmetric: mirrored and re-indexed, it is itself."""
    P = np.load(DATA / "reference_3d_68_points_trans.npy").astype(float)
    size = np.ptp(P, axis=0).max()
    x0 = P[:, 0].mean()  # its mirror plane x = x0 (the file is not exactly centred)
    mirrored = P.copy()
    mirrored[:, 0] = 2 * x0 - P[:, 0]
    err = np.linalg.norm(mirrored[SCHEMES["ibug68"]] - P, axis=1)
    assert err.mean() < 0.03 * size and err.max() < 0.1 * size
    # without re-indexing (or with a wrong one) the mirror is far off
    wrong = np.linalg.norm(mirrored - P, axis=1)
    assert wrong.mean() > 10 * err.mean()


def test_aflw21_agrees_with_ibug68_on_real_aflw2000(realdata):
    """AFLW2000-3D has both its 21 AFLW points (pt2d) and 68 fitted iBUG points (pt3d_68) per image.

    Each AFLW point is matched to its nearest iBUG proxy (68 points plus the two eye centres as
    face70's pupils); the AFLW mirror partner must then sit next to the iBUG mirror partner.
    """
    from hpe_cli.datasets.mat import read_mat

    files = sorted((realdata / "aflw2000_prnet").glob("*.mat"))
    assert files
    dists = []
    for f in files:
        m = read_mat(f)
        q = m["pt3d_68"][:2].T
        q = np.vstack([q, q[36:42].mean(0), q[42:48].mean(0)])  # 70 proxies
        p = m["pt2d"].T  # (21, 2), NaN = invisible
        dists.append(np.linalg.norm(p[:, None] - q[None], axis=2))
    d = np.nanmedian(np.stack(dists), axis=0)  # (21, 70) median over images where visible
    nearest = d.argmin(axis=1)
    face_size = np.nanmedian([np.ptp(read_mat(f)["pt3d_68"][0]) for f in files])
    assert np.all(d[np.arange(21), nearest] < 0.08 * face_size)  # every AFLW point has an iBUG proxy
    p21, p70 = SCHEMES["aflw21"], SCHEMES["face70"]
    partner = d[p21, p70[nearest]]  # AFLW partner of k vs iBUG partner of k's proxy
    assert np.all(partner < 0.1 * face_size), partner
    # the identity would pair points across the face
    changed = p21 != np.arange(21)
    assert np.all(d[np.arange(21), p70[nearest]][changed] > 0.15 * face_size)


def test_flip_permutation_checks():
    assert np.array_equal(flip_permutation("aflw21", 21), SCHEMES["aflw21"])
    assert np.array_equal(flip_permutation([1, 0, 2]), [1, 0, 2])
    with pytest.raises(ValueError, match="has 68 landmarks, got 70"):
        flip_permutation("ibug68", 70)
    with pytest.raises(ValueError, match="expected a landmark scheme"):
        flip_permutation("ibug69")
    with pytest.raises(ValueError, match="own inverse"):
        check_permutation([1, 2, 0])
    with pytest.raises(ValueError, match="repeated or missing"):
        check_permutation([0, 0, 1])
    with pytest.raises(ValueError, match="integer"):
        check_permutation([0.0, 1.0])
    assert scheme_for_count(5) is None
