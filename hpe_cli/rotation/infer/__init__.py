"""Infer the rotation system behind a piece of code or a labelled dataset.

What can be observed
--------------------
A system's angles-to-matrix map (:meth:`RotationSystem.from_angles`) depends
on its three turns only: which role (pitch, yaw, roll) each turn takes, about
which of the system's axes, with which hand, and in which order the turns are
composed. The frame ``B`` and the storage (active or transposed) never enter
``from_angles``; they only say how the stored matrix relates to the canonical
300W-LP matrix (``to_canonical``). Hence:

- a *builder* (angles -> matrix, such as 6DRepNet's ``get_R``) or a table of
  angles with their matrices reveals the turns and their order, but not the
  frame nor the storage. The answer is the built-in system whose *stored*
  function equals the code's (its frame comes with its name: a SciPy-style
  Z-Y-X builder is ``scipy_zyx``, which lives in the frame ``T``), or a custom
  system in the frame and storage the caller names (canonical and active by
  default);
- a *decoder* (matrix -> angles, such as 3DDFA_V2's ``matrix2angle``) reveals
  the same, plus which of the two Euler solutions it returns (``selection``);
- angles with 3-D landmarks give a physical rotation in a known frame, so there
  the comparison goes through ``to_canonical`` and the result is a complete
  system (see :mod:`hpe_cli.geometry.template`).

The candidate space
-------------------
The search runs over every product ``R_a(s1 t1) @ R_b(s2 t2) @ R_c(s3 t3)``:
3! assignments of the roles to the three positions, 12 axis sequences (6
Tait-Bryan, 6 proper Euler), 2^3 hands (``s = +1`` right-handed, ``-1``
left-handed), angles ``t`` in degrees: 576 functions. The other switches of a
rotation system add no new function:

- *extrinsic*: extrinsic a-b-c with angles (t1, t2, t3) is intrinsic c-b-a with
  (t3, t2, t1), so the 576 extrinsic products are the same 576 functions;
- *transpose*: ``(R1 R2 R3).T = R3(-t3) R2(-t2) R1(-t1)``, again in the set;
- *a built-in frame*: every built-in frame is a signed permutation, and
  ``B.T @ R_axis(t) @ B`` is a turn about another coordinate axis, hand flipped
  or not, so conjugated products stay in the set too.

So the ``3! x 2^3 x 12 x 2 x 2`` combinations (times the built-in frames)
collapse to 576 distinct
functions (any two differ at almost every generic sample), and each is
evaluated once. All of them are built in one batched ``matmul`` of shape
``(576, N, 3, 3)``; with N = 64 that takes a few milliseconds.

Matching and ranking
--------------------
A builder matches a candidate when the Frobenius error between the code's
matrix and the candidate's is within ``tol`` on *every* sample (64 well-spread
angle triples over the full circle). A decoder is called on uniformly random
rotations ``R``; a candidate explains a sample when its matrix of the decoded
angles rebuilds ``R`` within ``tol``. Decoders often special-case the gimbal
lock (3DDFA_V2 forces roll to 0 when ``|R[2,0]| > 0.998``), so a sample the
candidate does not explain is excused when it lies in the candidate's own lock
zone (``|cos b|`` or ``|sin b|`` of the middle turn below :data:`LOCK_ZONE`,
within ~5.7 deg of the lock, about 0.5 % of random rotations). A candidate is
an exact fit when no sample is left unexplained and at least
:data:`MIN_EXPLAINED` of them are explained. A decoder that is wrong outside
the lock zones (SynergyNet's ``matrix2angle_corr``) is therefore rejected.
Tables of angles with matrices use the decoder rule (dataset labels are often
the output of a decoder), and their selection is read the same way.

Candidates are ranked by the number of unexplained samples, then by the median
error. Several built-ins may share one function (``300w_lp`` and ``whenet``
differ only in the solution they keep); ties are broken by the decoder's
observed selection, then by the argument order and units matching the
system's storage order and units, then by a fixed priority.

Where it breaks
---------------
When nothing fits, the best partial fit is probed on structured inputs: for
each non-empty subset of the roles, random angles (10-60 deg, either sign) in
those roles and zero elsewhere. The report lists the subsets on which the code
agrees with the candidate and those on which it does not, with the largest
error and, for decoders, which output angles are wrong.

Landmarks
---------
With 3-D landmarks there is no exact answer: a template fitted to each face
gives an observed active rotation ``R_n`` in the canonical frame, with a degree
or two of noise. Each candidate ``g`` (now read as labels -> canonical matrix)
is scored by the geodesic residuals ``angle(g(labels_n) @ Q, R_n)``, where the
single rotation ``Q`` absorbs the template's own small tilt in the head frame
(fitted per candidate in closed form, so no candidate is favoured, and only
kept when under :data:`MAX_TEMPLATE_OFFSET_DEG`). The ranking uses the RMS
residual: orders of the same turns agree on small angles, and only the faces
with two large angles tell them apart, so a median would hide exactly the
decisive faces. The verdict is ``clear`` when the runner-up's RMS residual is
:data:`CLEAR_SEPARATION` times the winner's, ``poor`` when the winner's exceeds
:data:`POOR_RESIDUAL_DEG` or the template does not fit the landmarks, else
``ambiguous``. Built-in names come from each built-in's own
``to_canonical(from_angles(.))``; the report also lists each built-in's stored
matrix read directly as the canonical rotation (6DRepNet's ``get_R`` read that
way is the transpose of 300W-LP's matrix).

The package is split by mode: :mod:`.core` (candidates, samples, scores, reports),
:mod:`.code` (builders), :mod:`.decoders`, :mod:`.data` (tables), :mod:`.landmarks` and
:mod:`.storage` (decoders returning stored values); every name is importable from here.
"""

from __future__ import annotations

from .code import as_builder, infer_builder
from .core import (
    CODE_TOL,
    DATA_TOL,
    LOCK_ZONE,
    MIN_EXPLAINED,
    PRIORITY,
    SEARCH_ROWS,
    SEQUENCES,
    CallError,
    Candidate,
    Scores,
    builtin_canonical_by_candidate,
    builtin_names_by_candidate,
    candidate_locks,
    candidate_matrices,
    candidate_of,
    candidates,
    probe_builder,
    probe_decoder,
    random_rotations,
    report_json,
    score,
    spread_angles,
)
from .data import infer_table
from .decoders import as_decoder, infer_decoder
from .landmarks import (
    CLEAR_SEPARATION,
    MAX_TEMPLATE_OFFSET_DEG,
    MIN_FACES_FOR_OFFSET,
    POOR_RESIDUAL_DEG,
    infer_landmarks,
    polar_rotation,
)
from .storage import STORAGE_FORMS, as_value_decoder, infer_storage_decoder

__all__ = [
    "CLEAR_SEPARATION",
    "CODE_TOL",
    "DATA_TOL",
    "LOCK_ZONE",
    "MAX_TEMPLATE_OFFSET_DEG",
    "MIN_EXPLAINED",
    "MIN_FACES_FOR_OFFSET",
    "POOR_RESIDUAL_DEG",
    "PRIORITY",
    "SEARCH_ROWS",
    "SEQUENCES",
    "STORAGE_FORMS",
    "CallError",
    "Candidate",
    "Scores",
    "as_builder",
    "as_decoder",
    "as_value_decoder",
    "builtin_canonical_by_candidate",
    "builtin_names_by_candidate",
    "candidate_locks",
    "candidate_matrices",
    "candidate_of",
    "candidates",
    "infer_builder",
    "infer_decoder",
    "infer_landmarks",
    "infer_storage_decoder",
    "infer_table",
    "polar_rotation",
    "probe_builder",
    "probe_decoder",
    "random_rotations",
    "report_json",
    "score",
    "spread_angles",
]
