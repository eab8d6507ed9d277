"""``hpe export``: training-ready datasets in the layout each trainer reads (crops, splits, sampling).

The job runs in four stages, one module each:

1. :mod:`.inputs` -- read every input into one label table (image, box, canonical matrix ``A``, landmarks,
   groups);
2. :mod:`.select` -- express the labels in the layout's rotation system through the matrices (never by editing
   angles), apply the layout's own rules, the split, ``--min-change`` and ``--balance`` (rules in
   :mod:`.sampling`);
3. :mod:`.pixels` / :mod:`.workers` -- decode each source image once (:mod:`hpe_cli.io.images` finds it, the resolver draw and augment use), crop every head in
   it (padding outside the frame), encode;
4. :mod:`.write` -- let the layout write its index files, then ``export.json`` and the rejects.

Everything goes into a staging folder that replaces OUT_DIR only at the end; every input label that is not
exported is a reject with its reason. :func:`run_export` (:mod:`.job`) runs the stages.
"""

from __future__ import annotations

from ...io.images import jpeg_size, resolve_image, video_path
from .inputs import load_inputs, load_mat_input, load_table_input, load_w300lp_input
from .job import run_export
from .options import ExportOptions
from .sampling import (
    assign_splits,
    balance_keep,
    check_split_names,
    group_hash,
    is_choice,
    min_change_keep,
    parse_balance,
    parse_split,
    read_split_file,
)
from .write import staged_dir

__all__ = [
    "ExportOptions",
    "assign_splits",
    "balance_keep",
    "check_split_names",
    "group_hash",
    "is_choice",
    "jpeg_size",
    "load_inputs",
    "load_mat_input",
    "load_table_input",
    "load_w300lp_input",
    "min_change_keep",
    "parse_balance",
    "parse_split",
    "read_split_file",
    "resolve_image",
    "run_export",
    "staged_dir",
    "video_path",
]
