"""A rigid 68-point face template and its rotation fit to 3-D landmarks.

The template
------------
``hpe_cli/data/reference_3d_68_points_trans.npy`` (DirectMHP's mean iBUG-68
face, 68 x 3 float32) ships without a documented frame. Read off its points:

- point 0 (the subject's right jaw corner, seen on the image left) has
  x = -0.74 and point 16 (left jaw corner) x = +0.73: **x points to the image
  right** (the subject's left);
- the chin (point 8) has y = +0.70 and the brows (19, 24) y = -0.62:
  **y points down**;
- the nose tip (point 30) has z = -0.75 and the jaw corners z = +0.4:
  **z points into the head**, away from a camera the face looks at.

That is the OpenCV camera frame for a frontal face, ``F = diag(1, -1, -1)``
away from the canonical 300W-LP frame (x subject's left, y up, z out of the
face), so :func:`reference_template` returns ``points @ F``. Units are about
half a face width (outer eye corners at x = +-0.42). Fitted to the 16
AFLW2000-3D faces in ``realdata/aflw2000_prnet``, it agrees with ``Pose_Para``
to 0.6-3.6 deg, and to 0.2-2.1 deg once one constant rotation of 2.0 deg
(mostly pitch: the template's "frontal" face is slightly tilted relative to the
Basel Face Model's axes) is allowed; :func:`hpe_cli.rotation.infer.infer_landmarks`
fits that constant per hypothesis, so no hypothesis is favoured by it.
Using an external template rather than one built from the data avoids a
circular answer: a template averaged from faces de-rotated by one system's
reading of the labels would favour that system by construction.

Landmark frames
---------------
AFLW2000-3D ``pt3d_68`` rows are image x (right), image y (rows, *down*) and
depth, which grows towards the camera (the nose tip has the largest depth):
a left-handed frame. Negating y gives the canonical frame; see
:data:`LANDMARK_FRAMES`.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.resources import files

import numpy as np

from .similarity import fit_similarity

#: median fit RMSE (template units) above which landmarks do not look like the template: about 0.1 on
#: AFLW2000-3D, about 0.9 when a wrong landmark frame mirrors the faces
POOR_FIT_RMSE = 0.3

#: per-axis signs mapping landmark coordinates to the canonical frame
LANDMARK_FRAMES = {
    "image": (1.0, -1.0, 1.0),  # x right, y down, z towards the camera (AFLW2000-3D pt3d_68)
    "canonical": (1.0, 1.0, 1.0),  # x right, y up, z towards the camera (300W-LP / BFM)
    "opencv": (1.0, -1.0, -1.0),  # x right, y down, z away from the camera
}


@lru_cache(maxsize=1)
def _reference() -> np.ndarray:

    with (files("hpe_cli.data") / "reference_3d_68_points_trans.npy").open("rb") as fh:
        return np.load(fh).astype(np.float64)


def reference_template() -> np.ndarray:
    """The 68-point template in the canonical frame, shape (68, 3) (a fresh copy)."""
    return _reference() * np.array(LANDMARK_FRAMES["opencv"])


def to_canonical_points(points, frame: str = "image") -> np.ndarray:
    """Map ``(..., 3)`` landmark coordinates given in ``frame`` to the canonical frame."""
    try:
        signs = LANDMARK_FRAMES[frame]
    except KeyError:
        raise ValueError(f"expected a landmark frame in {sorted(LANDMARK_FRAMES)}, got {frame!r}") from None
    return np.asarray(points, dtype=np.float64) * np.array(signs)


def fit_template(points_canonical, template=None) -> dict:
    """Fit ``points ~= scale * R @ template + t`` for each face.

    Parameters
    ----------
    points_canonical : array_like, shape (N, 68, 3)
        Landmarks in the canonical frame (NaN marks a missing point).
    template : array_like, shape (68, 3), optional
        Defaults to :func:`reference_template`.

    Returns
    -------
    dict
        ``R`` (N, 3, 3) the active rotation of each face in the canonical
        frame, ``scale`` (N,), ``rmse`` (N,) in landmark units and
        ``rmse_rel`` (N,) the RMSE in template units (``rmse / scale``;
        about 0.1 on AFLW2000-3D), ``n_pairs`` (N,).
    """

    P = np.asarray(points_canonical, dtype=np.float64)
    if P.ndim != 3 or P.shape[1:] != (68, 3):
        raise ValueError(f"expected landmarks of shape (N, 68, 3), got {P.shape}")
    T = reference_template() if template is None else np.asarray(template, dtype=np.float64)
    fit = fit_similarity(np.broadcast_to(T, P.shape), P)
    with np.errstate(invalid="ignore", divide="ignore"):
        fit["rmse_rel"] = fit["rmse"] / fit["scale"]
    return fit
