"""Drawing geometry (hpe_cli.geometry.draw) against Hopenet's and 6DRepNet's formulas and rendered pixels."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy import cos, sin

from hpe_cli.geometry import draw as g
from hpe_cli.rotation import get_system

W300 = get_system("300w_lp")


def canonical(pyr, system="300w_lp"):
    s = get_system(system)
    return s.to_canonical(s.from_angles(np.atleast_2d(pyr)))


def hopenet_ends(pitch, yaw, roll, tdx, tdy, size):
    """Oracle: Hopenet's draw_axis end points, written out from its formula (SPEC §4, paper §5).

    It takes 300W-LP degrees, negates yaw, and projects three rotated unit vectors.
    """
    p, y, r = np.deg2rad(pitch), -np.deg2rad(yaw), np.deg2rad(roll)
    red = (size * cos(y) * cos(r) + tdx, size * (cos(p) * sin(r) + cos(r) * sin(p) * sin(y)) + tdy)
    green = (size * -cos(y) * sin(r) + tdx, size * (cos(p) * cos(r) - sin(p) * sin(y) * sin(r)) + tdy)
    blue = (size * sin(y) + tdx, size * -cos(y) * sin(p) + tdy)
    return np.array([red, green, blue])


def pose_cube_corners(pitch, yaw, roll, tdx, tdy, size):
    """Oracle: the 8 points 6DRepNet's plot_pose_cube connects (base corner at tdx - size/2, tdy - size/2)."""
    ends = hopenet_ends(pitch, yaw, roll, 0.0, 0.0, size)
    o = np.array([tdx - 0.5 * size, tdy - 0.5 * size])
    return {(a, b, c): o + a * ends[0] + b * ends[1] + c * ends[2] for a in (0, 1) for b in (0, 1) for c in (0, 1)}


angles = st.tuples(st.floats(-180, 180), st.floats(-90, 90), st.floats(-180, 180))


@settings(max_examples=80, deadline=None)
@given(st.lists(angles, min_size=1, max_size=16), st.floats(-500, 500), st.floats(-500, 500), st.floats(1, 300))
def test_axes_equal_hopenet_draw_axis(triples, tdx, tdy, size):
    pyr = np.array(triples)
    ends = g.axis_endpoints(canonical(pyr), np.tile([tdx, tdy], (len(pyr), 1)), size)
    for n, (p, y, r) in enumerate(pyr):
        np.testing.assert_allclose(ends[n], hopenet_ends(p, y, r, tdx, tdy, size), atol=1e-9)


def test_spec_columns_of_A():
    A = canonical([20, -50, 15])[0]
    ends = g.axis_endpoints(A[None], [[0, 0]], 1.0)[0]
    np.testing.assert_allclose(ends, [[A[0, 0], -A[1, 0]], [-A[0, 1], A[1, 1]], [A[0, 2], -A[1, 2]]], atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(angles, st.floats(1, 200))
def test_hopenet_anchored_cube_equals_plot_pose_cube(pyr, L):
    corners, _ = g.cube_corners(canonical(pyr), [[100.0, 50.0]], L, anchor="hopenet")
    oracle = pose_cube_corners(*pyr, 100.0, 50.0, 2 * L)
    for k, bits in enumerate(g.CUBE_BITS):
        np.testing.assert_allclose(corners[0, k], oracle[tuple(bits)], atol=1e-9)


def test_centred_cube_is_centred_and_has_edges_2L():
    A = canonical([[13, 140, -33]], "whenet")
    corners, depth = g.cube_corners(A, [[10.0, 20.0]], 5.0)
    np.testing.assert_allclose(corners[0].mean(axis=0), [10, 20], atol=1e-12)
    np.testing.assert_allclose(depth[0].mean(), 0, atol=1e-12)
    V = g.image_vectors(A)[0]
    for k0, k1 in g.CUBE_EDGES:  # every edge is 2L long in 3-D
        d3 = 5.0 * (2 * g.CUBE_BITS[k1] - 2 * g.CUBE_BITS[k0]) @ V
        assert np.linalg.norm(d3) == pytest.approx(10.0)


def test_physical_signs():
    # SPEC §2: +yaw turns the nose to the image left, +pitch raises it, +roll tilts the head top to the image right
    nose = lambda pyr: g.axis_endpoints(canonical(pyr), [[0, 0]], 1.0)[0, 2]  # noqa: E731
    assert nose([0, 30, 0])[0] < 0
    assert nose([30, 0, 0])[1] < 0  # rows go down: up is negative v
    chin = g.axis_endpoints(canonical([0, 0, 20]), [[0, 0]], 1.0)[0, 1]
    assert chin[0] < 0 and chin[1] > 0  # top to the right means the chin swings to the left
    left = g.axis_endpoints(canonical([0, 0, 0]), [[0, 0]], 1.0)[0, 0]
    np.testing.assert_allclose(left, [1, 0], atol=1e-15)  # the subject's left is the image right


@pytest.mark.parametrize("system", ["6drepnet", "opencv", "scipy_zyx", "3ddfa_v2"])
def test_same_drawing_from_every_system(system):
    rng = np.random.default_rng(3)
    pyr = np.column_stack([rng.uniform(-80, 80, 20), rng.uniform(-85, 85, 20), rng.uniform(-80, 80, 20)])
    A = canonical(pyr)
    s = get_system(system)
    A2 = s.to_canonical(s.from_canonical(A))  # the other system's stored matrix, mapped back
    np.testing.assert_allclose(
        g.axis_endpoints(A2, np.zeros((20, 2)), 50), g.axis_endpoints(A, np.zeros((20, 2)), 50), atol=1e-9
    )


def test_visibility_front_and_back():
    front = canonical([[0, 0, 0], [10, 40, 5]])
    back = canonical([[0, 180, 0], [10, 140, 5]], "whenet")
    assert g.face_front_visible(front).all()
    assert not g.face_front_visible(back).any()
    faces, edges = g.cube_visibility(canonical([[0, 0, 0]]))
    assert faces[0, 2, 1] and not faces[0, 2, 0]
    front_square = g.CUBE_EDGE_KIND == 2
    assert edges[0][front_square].all() and not edges[0][~front_square].any()


@settings(max_examples=40, deadline=None)
@given(angles)
def test_generic_view_shows_three_faces_and_nine_edges(pyr):
    A = canonical(pyr)
    w = g.axis_depth(A)[0]
    if np.abs(w).min() < 1e-6:
        return  # a face seen edge-on
    faces, edges = g.cube_visibility(A)
    assert faces[0].sum() == 3 and (faces[0].sum(axis=1) == 1).all()
    assert edges[0].sum() == 9
    # the corner nearest the viewer touches only visible edges, the farthest only hidden ones
    _, depth = g.cube_corners(A, [[0, 0]], 1.0)
    near, far = np.argmax(depth[0]), np.argmin(depth[0])
    touches = lambda k: (g.CUBE_EDGES == k).any(axis=1)  # noqa: E731
    assert edges[0][touches(near)].all() and not edges[0][touches(far)].any()


def test_rendered_axis_colours():
    img = g.blank_canvas(200, 200)
    g.render_axes(img, canonical([[0, 0, 0]]), [[100, 100]], 80, thickness=5)
    assert tuple(img[100, 160]) == g.RED  # to the image right
    assert tuple(img[160, 100]) == g.GREEN  # down
    assert tuple(img[40, 100]) == (255, 255, 255)  # nothing above the centre
    img = g.blank_canvas(200, 200)
    g.render_axes(img, canonical([[0, 90 - 1e-9, 0]]), [[100, 100]], 80, thickness=5)  # nose to the image left
    assert tuple(img[100, 40]) == g.BLUE
    assert tuple(img[160, 100]) == g.GREEN


def _edge_pixel(img, row, col):
    return tuple(int(v) for v in img[row, col])


def test_cube_turned_away_shows_the_back_square():
    # frontal and turned away project to the same square; only visibility tells them apart
    for pyr, system, colour in (
        ([0, 0, 0], "300w_lp", g.GREEN),
        ([0, 180, 0], "whenet", g.RED),
        ([180, 0, 180], "300w_lp", g.RED),
    ):
        img = g.blank_canvas(200, 200)
        g.render_cube(img, canonical([pyr], system), [[100, 100]], 50, thickness=5)
        assert _edge_pixel(img, 50, 100) == colour, (pyr, system)  # top edge
        assert _edge_pixel(img, 100, 150) == colour
        assert _edge_pixel(img, 100, 100) == (255, 255, 255)


def test_contact_sheet_layout():
    tiles = [np.full((40, 80, 3), v, np.uint8) for v in (10, 100, 200)]
    sheet = g.contact_sheet(tiles, cols=2, tile=64)
    assert sheet.shape == (128, 128, 3)
    assert tuple(sheet[32, 32]) == (10, 10, 10) and tuple(sheet[32, 96]) == (100, 100, 100)
    assert tuple(sheet[96, 32]) == (200, 200, 200) and tuple(sheet[96, 96]) == (32, 32, 32)
