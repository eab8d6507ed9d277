"""``hpe evaluate``: pair predictions with ground truth by key, score every pair, write the outputs.

Modules by concept: :mod:`.options` (:class:`EvaluateOptions`, the command's settings), :mod:`.run` (the
entry :func:`run_evaluate` and the passes), :mod:`.sides` (each side opened once, read in chunks), :mod:`.join` (the key join in memory),
:mod:`.lockstep` (files in the same order, paired as they stream), :mod:`.spill` (files in different orders:
the external hash join), :mod:`.score` (chunks scored on threads), :mod:`.rejects` (rows set aside),
:mod:`.outputs` (per-row table, worst rows, plot sample), :mod:`.dataset` (which dataset the GT is).
"""

from .join import JoinUsageError
from .options import EvaluateOptions
from .run import run_evaluate

__all__ = ["EvaluateOptions", "JoinUsageError", "run_evaluate"]
