"""``hpe infer``: find the rotation system a piece of code or a dataset uses.

The job, one module per concept:

- :mod:`.options` -- :class:`InferOptions`, the run's settings, validated once (built by the command line and
  the Python API alike);
- :mod:`.code` -- the user's ``--callable``/``--decoder`` loaded (:func:`load_callable`) and searched in a child
  process with a time limit (:func:`run_code_inference`);
- :mod:`.data` -- a data table read for the search (angles, matrix / stored / 3-D landmark columns), its
  unusable rows set aside as rejects, the table search or the landmark ranking;
- :mod:`.report` -- the summary lines, the JSON report and the system TOML written (:func:`finish`);
- :mod:`.job` -- :func:`run_infer`, the entry of the command and of the API.
"""

from __future__ import annotations

from .code import DEFAULT_TIMEOUT, load_callable, module_name_of, run_code_inference
from .job import run_infer
from .options import ROLE_NAMES, ROTATION_KINDS, InferOptions
from .report import finish, report_lines

__all__ = [
    "DEFAULT_TIMEOUT",
    "ROLE_NAMES",
    "ROTATION_KINDS",
    "InferOptions",
    "finish",
    "load_callable",
    "module_name_of",
    "report_lines",
    "run_code_inference",
    "run_infer",
]
