"""Pose drawings from the canonical matrix: three axis lines or a pose cube.

Geometry (pure numpy, batched)
------------------------------
A drawing needs only the canonical 300W-LP matrix ``A`` (SPEC §2, §4), never
the angles; any system's matrix is first mapped with ``system.to_canonical``.
The canonical frame has x = the subject's left, y = up, z = out of the face;
an image has u = right, v = down. With ``T = diag(1, -1, 1)`` the columns of
``T @ A @ T`` are three unit vectors in image coordinates ``(u, v, w)``, where
``w`` points from the image towards the viewer:

=====  =========================  ======================  ===============
line   3-D meaning                image direction          BGR colour
=====  =========================  ======================  ===============
red    the subject's left          ``(A00, -A10)``          (0, 0, 255)
green  forehead to chin            ``(-A01, A11)``          (0, 255, 0)
blue   out of the nose             ``(A02, -A12)``          (255, 0, 0)
=====  =========================  ======================  ===============

Each is scaled by the line length (pixels) and added to the head centre
(pixel coordinates, rows going down). For 300W-LP angles this is exactly what
Hopenet's ``draw_axis`` draws (also used by WHENet, 6DRepNet, DirectMHP).
The drawing is an orthographic projection, as the 300W-LP model is.

The pose cube is the cube spanned by the same three vectors. 6DRepNet's
``plot_pose_cube`` draws the square at the back of the head in red, the four
edges along the nose in blue and the square on the nose side ("face-front")
in green, always in that order, so a face turned away (|yaw| > 90) is drawn
as if it looked at the camera. Here each of the six faces is front-facing
when its outward normal has ``w > 0``, an edge is visible when one of its two
faces is front-facing (exact for a convex solid seen orthographically), hidden
edges are drawn dashed and thin first, and visible edges are drawn far to
near. The colours keep 6DRepNet's meaning: red back square, blue edges along
the nose, green face-front square.

Rendering
---------
``render_*`` draw onto a BGR ``uint8`` image with OpenCV (anti-aliased,
sub-pixel endpoints). They loop over the faces of one image only.
"""

from __future__ import annotations

import numpy as np

#: BGR colours of the three lines: the subject's left, forehead->chin, out of the nose
RED, GREEN, BLUE = (0, 0, 255), (0, 255, 0), (255, 0, 0)
AXIS_COLOURS = (RED, GREEN, BLUE)
AXIS_NAMES = ("left", "down", "nose")

#: corner k of the cube has bits (a, b, c) = (k & 1, k >> 1 & 1, k >> 2 & 1) along red, green, blue
CUBE_BITS = np.array([[k & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)])


def _cube_edges():
    edges, axis = [], []
    for ax in range(3):
        for k in range(8):
            if not CUBE_BITS[k, ax]:
                edges.append((k, k | (1 << ax)))
                axis.append(ax)
    return np.array(edges), np.array(axis)


#: (12, 2) corner pairs and (12,) the axis (0 red, 1 green, 2 blue) each edge runs along
CUBE_EDGES, CUBE_EDGE_AXIS = _cube_edges()
#: (12,) 0 = back square (red), 1 = edge along the nose (blue), 2 = face-front square (green)
CUBE_EDGE_KIND = np.where(CUBE_EDGE_AXIS == 2, 1, np.where(CUBE_BITS[CUBE_EDGES[:, 0], 2] == 1, 2, 0))
CUBE_KIND_COLOURS = (RED, BLUE, GREEN)

_T = np.diag([1.0, -1.0, 1.0])


def image_vectors(A) -> np.ndarray:
    """The three drawing vectors in image coordinates.

    Parameters
    ----------
    A : array_like, shape (N, 3, 3) or (3, 3)
        Canonical 300W-LP rotation matrices.

    Returns
    -------
    ndarray, shape (N, 3, 3)
        ``V[n, i]`` is line ``i`` (0 red = the subject's left, 1 green =
        forehead to chin, 2 blue = out of the nose) as ``(u, v, w)``: u to the
        image right, v down, w towards the viewer; unit length.
    """
    A = np.asarray(A, dtype=np.float64).reshape(-1, 3, 3)
    return np.swapaxes(_T @ A @ _T, -1, -2)


def axis_endpoints(A, centre, length) -> np.ndarray:
    """End points of the three lines, pixels.

    Parameters
    ----------
    A : array_like, shape (N, 3, 3)
        Canonical matrices.
    centre : array_like, shape (N, 2)
        Head centre ``(u, v)`` in pixels (column, row; rows go down).
    length : array_like, shape (N,) or scalar
        Line length in pixels, > 0.

    Returns
    -------
    ndarray, shape (N, 3, 2)
        ``[n, i]`` is the far end of line ``i`` (red, green, blue); each line
        starts at ``centre[n]``.
    """
    V = image_vectors(A)
    c = np.asarray(centre, dtype=np.float64).reshape(-1, 1, 2)
    L = np.asarray(length, dtype=np.float64).reshape(-1, 1, 1)
    return c + L * V[..., :2]


def axis_depth(A) -> np.ndarray:
    """``w`` of each line's far end, (N, 3): > 0 points towards the viewer."""
    return image_vectors(A)[..., 2]


def cube_corners(A, centre, length, anchor: str = "centre"):
    """Corners of the pose cube.

    Parameters
    ----------
    A : array_like, shape (N, 3, 3)
        Canonical matrices.
    centre : array_like, shape (N, 2)
        Head centre, pixels.
    length : array_like, shape (N,) or scalar
        Half the cube's edge, pixels (the axis line length).
    anchor : {"centre", "hopenet"}
        ``"centre"``: the cube is centred on ``centre`` and turns about it.
        ``"hopenet"``: the corner of the back square is fixed at
        ``centre - (length, length)`` as in 6DRepNet's ``plot_pose_cube``
        with ``size = 2 * length`` (centred only for a frontal face).

    Returns
    -------
    corners : ndarray, shape (N, 8, 2)
        Pixels; corner ``k`` has bits :data:`CUBE_BITS` ``[k]`` along red,
        green and blue.
    depth : ndarray, shape (N, 8)
        ``w`` of each corner relative to the centre, pixels (> 0: nearer the viewer).
    """
    V = image_vectors(A)
    c = np.asarray(centre, dtype=np.float64).reshape(-1, 1, 2)
    L = np.asarray(length, dtype=np.float64).reshape(-1, 1, 1)
    if anchor == "centre":
        coef = 2.0 * CUBE_BITS - 1.0
        pts = L * (coef @ V)  # (N, 8, 3)
        return c + pts[..., :2], pts[..., 2]
    if anchor == "hopenet":
        pts = 2.0 * L * (CUBE_BITS.astype(float) @ V)
        return c - L + pts[..., :2], pts[..., 2]
    raise ValueError(f"expected anchor 'centre' or 'hopenet', got {anchor!r}")


def cube_visibility(A, eps: float = 1e-9):
    """Which faces and edges of the cube face the viewer.

    Returns
    -------
    faces : ndarray of bool, shape (N, 3, 2)
        ``faces[n, axis, bit]``: the face at ``bit`` (0 = negative side,
        1 = positive side) of ``axis`` (0 red, 1 green, 2 blue) is
        front-facing. ``faces[:, 2, 1]`` is the face-front square (nose side).
    edges : ndarray of bool, shape (N, 12)
        Edge :data:`CUBE_EDGES` ``[e]`` is visible (one of its faces is front-facing).
    """
    w = axis_depth(A)  # (N, 3)
    faces = np.stack([w < -eps, w > eps], axis=-1)
    edges = np.zeros((len(w), len(CUBE_EDGES)), dtype=bool)
    for e, (k, _) in enumerate(CUBE_EDGES):
        for ax in range(3):
            if ax != CUBE_EDGE_AXIS[e]:
                edges[:, e] |= faces[:, ax, CUBE_BITS[k, ax]]
    return faces, edges


def face_front_visible(A, eps: float = 1e-9) -> np.ndarray:
    """True where the nose side of the head faces the viewer (``A[2, 2] > 0``)."""
    return axis_depth(A)[:, 2] > eps


# --------------------------------------------------------------------- rendering
_SHIFT = 4
_ONE = 1 << _SHIFT
_LIMIT = 1e6  # keep far-off points inside int32 after the sub-pixel shift


def _pt(p):
    p = np.clip(np.asarray(p, dtype=np.float64), -_LIMIT, _LIMIT)
    return int(round(p[0] * _ONE)), int(round(p[1] * _ONE))


def _line(img, p, q, colour, thickness):
    import cv2

    if np.isfinite(p).all() and np.isfinite(q).all():
        cv2.line(img, _pt(p), _pt(q), colour, int(thickness), cv2.LINE_AA, _SHIFT)


def _dashed(img, p, q, colour, thickness, dash):
    p, q = np.asarray(p, float), np.asarray(q, float)
    if not (np.isfinite(p).all() and np.isfinite(q).all()):
        return
    n = max(1, int(np.hypot(*(q - p)) // (2 * dash)))
    for s in np.linspace(0.0, 1.0, n + 1)[:-1]:
        a = p + (q - p) * s
        b = p + (q - p) * min(1.0, s + 0.5 / n)
        _line(img, a, b, colour, thickness)


def auto_thickness(length) -> int:
    """Line thickness in pixels for a line ``length`` pixels long (Hopenet uses 4 for ~100 px)."""
    if not np.isfinite(length):
        return 2
    return int(max(1, min(12, round(float(length) / 25.0))))


def render_axes(img, A, centre, length, thickness=None):
    """Draw the three lines of one or more faces onto ``img`` (BGR uint8, in place).

    The lines are drawn red, green, blue, in that order, as Hopenet's
    ``draw_axis`` does (so the nose line stays visible on a face turned away;
    the cube style shows what is in front).
    """
    ends = axis_endpoints(A, centre, length)
    centre = np.asarray(centre, dtype=np.float64).reshape(-1, 2)
    L = np.broadcast_to(np.asarray(length, dtype=np.float64), (len(ends),))
    for n in range(len(ends)):
        t = thickness or auto_thickness(L[n])
        for i in range(3):
            _line(img, centre[n], ends[n, i], AXIS_COLOURS[i], t)
    return img


def render_axes_dashed(img, A, centre, length, thickness=None):
    """Draw the three lines dashed, with a dot at each far end (a second pose on the same face, e.g. a
    prediction next to the solid ground truth). Same colours and geometry as :func:`render_axes`."""
    import cv2

    ends = axis_endpoints(A, centre, length)
    centre = np.asarray(centre, dtype=np.float64).reshape(-1, 2)
    L = np.broadcast_to(np.asarray(length, dtype=np.float64), (len(ends),))
    for n in range(len(ends)):
        t = thickness or max(1, auto_thickness(L[n]) // 2)
        for i in range(3):
            _dashed(img, centre[n], ends[n, i], AXIS_COLOURS[i], t, dash=max(4.0, 3.0 * t + 3))
            if np.isfinite(ends[n, i]).all():
                cv2.circle(img, _pt(ends[n, i]), max(3, 2 * t) * _ONE, AXIS_COLOURS[i], -1, cv2.LINE_AA, _SHIFT)
    return img


def render_legend(img, entries, height_px: float = 14.0):
    """A legend box in the top-left corner: one row per ``(label, style)``, style ``"solid"`` or ``"dashed"``,
    each with a sample of that line style in the three axis colours."""
    h = float(height_px)
    t = max(1, int(round(h / 7)))
    sample = 3.2 * h
    rows = len(entries)
    import cv2

    scale = max(0.3, h / 22.0)
    text_w = max(
        cv2.getTextSize(f"{label} ({style})", cv2.FONT_HERSHEY_SIMPLEX, scale, max(1, int(round(scale * 1.5))))[0][0]
        for label, style in entries
    )
    box_w, box_h = int(1.2 * h + sample + text_w + 4), int(rows * 1.6 * h + 0.6 * h)
    H, W = img.shape[:2]
    sub = img[0 : min(H, box_h), 0 : min(W, box_w)]
    sub[:] = (sub.astype(np.float32) * 0.35).astype(np.uint8)  # darken behind the legend
    for k, (label, style) in enumerate(entries):
        y = (k + 0.8) * 1.6 * h
        for i, colour in enumerate(AXIS_COLOURS):
            p = np.array([0.4 * h, y - h * 0.6 + i * h * 0.45])
            q = p + np.array([sample, 0.0])
            if style == "dashed":
                _dashed(img, p, q, colour, max(1, t), dash=max(3.0, 0.4 * h))
            else:
                _line(img, p, q, colour, t + 1)
        render_caption(img, f"{label} ({style})", (0.8 * h + sample, y), height_px=h)
    return img


def render_cube(img, A, centre, length, thickness=None, anchor: str = "centre"):
    """Draw the pose cube of one or more faces onto ``img`` (BGR uint8, in place).

    Hidden edges are dashed and thinner, drawn first; visible edges follow,
    far to near. Colours: back square red, edges along the nose blue,
    face-front square green.
    """
    corners, depth = cube_corners(A, centre, length, anchor)
    _, visible = cube_visibility(A)
    L = np.broadcast_to(np.asarray(length, dtype=np.float64), (len(corners),))
    edge_depth = depth[:, CUBE_EDGES].mean(axis=-1)
    for n in range(len(corners)):
        t = thickness or auto_thickness(L[n])
        th = max(1, t // 2)
        for e in np.flatnonzero(~visible[n]):
            k0, k1 = CUBE_EDGES[e]
            _dashed(
                img,
                corners[n, k0],
                corners[n, k1],
                CUBE_KIND_COLOURS[CUBE_EDGE_KIND[e]],
                th,
                dash=max(3.0, 2.0 * th + 2),
            )
        vis = np.flatnonzero(visible[n])
        for e in vis[np.argsort(edge_depth[n, vis], kind="stable")]:
            k0, k1 = CUBE_EDGES[e]
            _line(img, corners[n, k0], corners[n, k1], CUBE_KIND_COLOURS[CUBE_EDGE_KIND[e]], t)
    return img


def render_caption(img, text, origin, height_px: float = 14.0, colour=(255, 255, 255), outline=(0, 0, 0)):
    """Write ``text`` with an outline at ``origin`` (u, v of the baseline start), kept inside ``img``."""
    import cv2

    scale = max(0.3, height_px / 22.0)
    th = max(1, int(round(scale * 1.5)))
    (tw, tht), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, th)
    H, W = img.shape[:2]
    u = int(round(min(max(float(origin[0]), 2.0), max(2.0, W - tw - 2.0)))) if np.isfinite(origin[0]) else 2
    v = (
        int(round(min(max(float(origin[1]), tht + 2.0), max(tht + 2.0, H - base - 2.0))))
        if np.isfinite(origin[1])
        else tht + 2
    )
    # a thicker stroke also widens OpenCV's glyph advance, so outline by offsetting instead
    for du, dv in ((-1, -1), (-1, 1), (1, -1), (1, 1), (0, 2), (0, -2), (2, 0), (-2, 0)):
        cv2.putText(img, text, (u + du, v + dv), cv2.FONT_HERSHEY_SIMPLEX, scale, outline, th, cv2.LINE_AA)
    cv2.putText(img, text, (u, v), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, th, cv2.LINE_AA)
    return img


def blank_canvas(width: int, height: int, value: int = 255) -> np.ndarray:
    """A ``height x width`` BGR image filled with ``value`` (white by default)."""
    return np.full((int(height), int(width), 3), value, dtype=np.uint8)


def contact_sheet(tiles, cols: int, tile: int = 256, captions=None, background: int = 32) -> np.ndarray:
    """Tile BGR images into one sheet.

    Parameters
    ----------
    tiles : sequence of ndarray
        BGR uint8 images of any size; each is scaled (aspect kept) into a
        ``tile x tile`` cell.
    cols : int
        Cells per row, >= 1.
    tile : int
        Cell size in pixels.
    captions : sequence of str, optional
        One caption per image, written at the bottom of its cell.
    """
    import cv2

    n = len(tiles)
    cols = max(1, min(int(cols), n))
    rows = -(-n // cols)
    sheet = np.full((rows * tile, cols * tile, 3), background, dtype=np.uint8)
    for i, im in enumerate(tiles):
        h, w = im.shape[:2]
        s = tile / max(h, w)
        nh, nw = max(1, int(round(h * s))), max(1, int(round(w * s)))
        small = cv2.resize(im, (nw, nh), interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
        r0, c0 = (i // cols) * tile + (tile - nh) // 2, (i % cols) * tile + (tile - nw) // 2
        sheet[r0 : r0 + nh, c0 : c0 + nw] = small
        if captions is not None and captions[i]:
            cell = sheet[(i // cols) * tile : (i // cols + 1) * tile, (i % cols) * tile : (i % cols + 1) * tile]
            render_caption(cell, str(captions[i])[:40], (4, tile - 4), height_px=max(9.0, tile / 20.0))
    return sheet
