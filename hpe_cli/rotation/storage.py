"""Storage forms of a rotation: rotation vectors, quaternions, 6-D, 3x3/4x4 matrices.

Pure numpy, vectorised over a leading batch axis. Every function takes and
returns float64 arrays; matrices are active rotations ``(N, 3, 3)``.

- **rotvec**: axis times angle, radians (OpenCV ``Rodrigues``, SciPy ``as_rotvec``).
- **quaternion**: unit quaternion, ``order="wxyz"`` (scalar first) or ``"xyzw"``
  (scalar last, SciPy's order). Outputs are normalised to ``w >= 0``.
- **6d**: two columns of the matrix (Zhou et al. 2019; 6DRepNet's
  ``compute_rotation_matrix_from_ortho6d`` uses columns 0 and 1), rebuilt by
  Gram-Schmidt on input; the third column is the cross product that makes
  ``det = +1``.
- **matrix4**: the rotation block ``M[:3, :3]`` of a 4x4 homogeneous matrix.
"""

from __future__ import annotations

import numpy as np

QUATERNION_ORDERS = ("wxyz", "xyzw")


def _as_batch(x, width, name):
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-1:] != (width,):
        raise ValueError(f"expected {name} of shape (..., {width}), got {x.shape}")
    return x


# ------------------------------------------------------------------ rotvec
def rotvec_to_soa(x, y, z):
    """Rotation matrices as a nested list of 1-D arrays (see :mod:`hpe_cli.rotation.soa`) from rotvec columns.

    ``R = I + (sin t / t) K + ((1 - cos t) / t^2) K^2`` with ``K`` the cross-product
    matrix of the vector and ``t`` its norm; both coefficients use their Taylor
    series below ``t = 1e-4`` so that small vectors stay exact to machine precision.
    """
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (x, y, z))
    t2 = x * x + y * y + z * z
    t = np.sqrt(t2)
    small = t < 1e-4
    if small.any():
        ts = np.where(small, 1.0, t)
        a = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(ts) / ts)
        b = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - np.cos(ts)) / (ts * ts))
    else:
        a = np.sin(t) / t
        b = (1.0 - np.cos(t)) / t2
    bx, by, bz = b * x, b * y, b * z
    ax, ay, az = a * x, a * y, a * z
    return _soa_from_products(bx * x, by * y, bz * z, bx * y, bx * z, by * z, ax, ay, az)


def _soa_from_products(xx, yy, zz, xy, xz, yz, sx, sy, sz):
    """``I + [s]x + (symmetric part)`` as nested lists ``X[row][col]`` of 1-D arrays: the matrix both Rodrigues' formula
    (``s = sin(t) v / t``, products scaled by ``(1 - cos t) / t^2``) and the quaternion formula (``s = w v * 2/|q|^2``,
    products scaled by ``2/|q|^2``) reduce to."""
    return [
        [1.0 - (yy + zz), xy - sz, xz + sy],
        [xy + sz, 1.0 - (xx + zz), yz - sx],
        [xz - sy, yz + sx, 1.0 - (xx + yy)],
    ]


def _soa_to_array(X, shape):
    out = np.empty(shape + (3, 3))
    flat = out.reshape(-1, 3, 3)
    for m in range(3):
        for k in range(3):
            flat[:, m, k] = X[m][k]
    return out


def rotvec_to_matrix(rotvec) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` in radians (see :func:`rotvec_to_soa`)."""
    v = _as_batch(rotvec, 3, "rotation vectors")
    flat = v.reshape(-1, 3)
    return _soa_to_array(rotvec_to_soa(flat[:, 0], flat[:, 1], flat[:, 2]), v.shape[:-1])


def matrix_to_rotvec(R) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` (radians, angle in [0, pi]) of matrices ``(..., 3, 3)``.

    Goes through the quaternion (Shepperd's branch choice), so it is stable near
    0 and near pi; at exactly pi the sign of the axis follows the quaternion's.
    """
    q = matrix_to_quaternion(R, order="wxyz")
    w, v = q[..., 0], q[..., 1:]
    n = np.sqrt(np.einsum("...i,...i->...", v, v))
    angle = 2.0 * np.arctan2(n, w)
    small = angle < 1e-3
    a2 = angle * angle
    scale = np.where(small, 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0, angle / np.where(small, 1.0, n))
    return v * scale[..., None]


# -------------------------------------------------------------- quaternion
def _check_order(order):
    if order not in QUATERNION_ORDERS:
        raise ValueError(f"expected quaternion order 'wxyz' or 'xyzw', got {order!r}")


def quaternion_to_soa(w, x, y, z):
    """Rotation matrices as a nested list of 1-D arrays from quaternion columns (normalised first)."""
    w, x, y, z = (np.asarray(v, dtype=np.float64) for v in (w, x, y, z))
    n2 = w * w + x * x + y * y + z * z
    s = 2.0 / n2
    xs, ys, zs = x * s, y * s, z * s
    return _soa_from_products(x * xs, y * ys, z * zs, x * ys, x * zs, y * zs, w * xs, w * ys, w * zs)


def quaternion_to_matrix(q, order: str = "wxyz") -> np.ndarray:
    """Rotation matrices from quaternions ``(..., 4)`` in ``order``; normalised first."""
    _check_order(order)
    q = _as_batch(q, 4, "quaternions")
    flat = q.reshape(-1, 4)
    cols = (
        (flat[:, 0], flat[:, 1], flat[:, 2], flat[:, 3])
        if order == "wxyz"
        else (flat[:, 3], flat[:, 0], flat[:, 1], flat[:, 2])
    )
    return _soa_to_array(quaternion_to_soa(*cols), q.shape[:-1])


def matrix_to_quaternion(R, order: str = "wxyz") -> np.ndarray:
    """Unit quaternions ``(..., 4)`` with ``w >= 0`` of rotation matrices ``(..., 3, 3)``.

    Shepperd's method: each row uses the largest of ``trace, R00, R11, R22`` as
    its pivot, so no branch divides by a small number.
    """
    _check_order(order)
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected matrices of shape (..., 3, 3), got {R.shape}")
    shape = R.shape[:-2]
    M = R.reshape(-1, 3, 3)
    d = np.stack([M[:, 0, 0], M[:, 1, 1], M[:, 2, 2], M[:, 0, 0] + M[:, 1, 1] + M[:, 2, 2]], axis=-1)
    k = np.argmax(d, axis=-1)
    q = np.empty((M.shape[0], 4))  # x, y, z, w
    t = k == 3
    if t.any():
        m = M[t]
        q[t, 3] = 1 + d[t, 3]
        q[t, 0] = m[:, 2, 1] - m[:, 1, 2]
        q[t, 1] = m[:, 0, 2] - m[:, 2, 0]
        q[t, 2] = m[:, 1, 0] - m[:, 0, 1]
    for i in range(3):
        s = k == i
        if not s.any():
            continue
        j, l = (i + 1) % 3, (i + 2) % 3
        m = M[s]
        q[s, i] = 1 - d[s, 3] + 2 * m[:, i, i]
        q[s, j] = m[:, j, i] + m[:, i, j]
        q[s, l] = m[:, l, i] + m[:, i, l]
        q[s, 3] = m[:, l, j] - m[:, j, l]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[q[:, 3] < 0] *= -1.0
    out = q if order == "xyzw" else q[:, [3, 0, 1, 2]]
    return out.reshape(shape + (4,))


def canonical_quaternion(q, order: str = "wxyz") -> np.ndarray:
    """Normalise quaternions to unit length and ``w >= 0`` (the same rotation)."""
    _check_order(order)
    q = _as_batch(q, 4, "quaternions")
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w = q[..., 0] if order == "wxyz" else q[..., 3]
    return np.where((w < 0)[..., None], -q, q)


# ---------------------------------------------------------------------- 6-D
def check_sixd_pair(columns):
    """The two matrix columns a 6-D storage keeps, as ints, checked (two different of 0, 1, 2)."""
    cols = tuple(int(c) for c in columns)
    if len(cols) != 2 or cols[0] == cols[1] or not all(0 <= c <= 2 for c in cols):
        raise ValueError(f"expected two different matrix columns out of 0, 1, 2, got {list(columns)}")
    return cols


def sixd_to_matrix(d6, columns=(0, 1)) -> np.ndarray:
    """Rotation matrices from 6-D vectors ``(..., 6)``: two matrix columns, Gram-Schmidt.

    ``d6[..., 0:3]`` is matrix column ``columns[0]`` (normalised as is),
    ``d6[..., 3:6]`` is column ``columns[1]`` (its part orthogonal to the first,
    normalised); the remaining column completes a right-handed basis.
    Degenerate inputs (a zero first vector, or parallel vectors) give NaN rows.
    """
    i, j = check_sixd_pair(columns)
    d6 = _as_batch(d6, 6, "6-D vectors")
    a, b = d6[..., 0:3], d6[..., 3:6]
    with np.errstate(invalid="ignore", divide="ignore"):
        x = a / np.linalg.norm(a, axis=-1, keepdims=True)
        b = b - np.einsum("...i,...i->...", x, b)[..., None] * x
        y = b / np.linalg.norm(b, axis=-1, keepdims=True)
    cols = [None, None, None]
    cols[i], cols[j] = x, y
    k = 3 - i - j
    cols[k] = np.cross(cols[(k + 1) % 3], cols[(k + 2) % 3])
    return np.stack(cols, axis=-1)


def matrix_to_sixd(R, columns=(0, 1)) -> np.ndarray:
    """The two matrix columns ``columns`` of ``R`` as ``(..., 6)``."""
    i, j = check_sixd_pair(columns)
    R = np.asarray(R, dtype=np.float64)
    return np.concatenate([R[..., :, i], R[..., :, j]], axis=-1)


# -------------------------------------------------------------------- 4x4
def matrix4_to_matrix(M) -> np.ndarray:
    """The rotation block ``M[..., :3, :3]`` of 4x4 homogeneous matrices."""
    M = np.asarray(M, dtype=np.float64)
    if M.shape[-2:] != (4, 4):
        raise ValueError(f"expected matrices of shape (..., 4, 4), got {M.shape}")
    return M[..., :3, :3].copy()


def matrix_to_matrix4(R, t=None) -> np.ndarray:
    """4x4 homogeneous matrices with rotation ``R`` and translation ``t`` (default 0)."""
    R = np.asarray(R, dtype=np.float64)
    M = np.zeros(R.shape[:-2] + (4, 4))
    M[..., :3, :3] = R
    if t is not None:
        M[..., :3, 3] = t
    M[..., 3, 3] = 1.0
    return M
