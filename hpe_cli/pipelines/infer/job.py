"""``hpe infer``'s job: run the search on the user's code (in a child process) or on a data table."""

from __future__ import annotations

from ...errors import HpeError, UsageError
from ...rotation import infer as inf
from ..pools import library_threads
from .code import DEFAULT_TIMEOUT, code_file, run_code_inference
from .data import infer_data, read_data_table, set_aside_unusable
from .options import InferOptions


def run_infer(data, spec, opts: InferOptions) -> dict:
    """The infer report of user code (``spec``: ``FILE.py:FUNC`` or ``module:FUNC``) or of a data table (``data``).

    Exactly one of ``data`` and ``spec`` is given; ``opts`` holds ``hpe infer``'s options
    (:class:`~hpe_cli.pipelines.infer.options.InferOptions`).

    Returns
    -------
    dict
        The report of :mod:`hpe_cli.rotation.infer`, with ``_system_toml`` and
        ``_system_name`` (None when nothing fits exactly).
    """
    if (data is None) == (spec is None):
        raise UsageError(
            "expected exactly one of DATA and the code (FILE.py:FUNC), got " + ("both" if spec else "none")
        )
    if spec is not None:
        return _infer_code(spec, opts)
    if opts.returns != "angles" or opts.builder:
        raise UsageError("returns and builder apply to code only, not to DATA")
    # lazy: the table side (pyarrow, the .mat reader, the template fit) is no part of a --callable/--decoder run,
    # whose parent and child both load this package (measured: +0.5 to 3 s and +27 MB per run when eager)

    with library_threads(opts.threads):
        table = set_aside_unusable(read_data_table(data, opts), opts)
        try:
            rep = infer_data(table, opts)
        except ValueError as exc:
            raise HpeError(f"{data}: {exc}") from None
    system = rep.get("_system")
    rep["_system_toml"] = system.to_toml() if system is not None else None
    rep["_system_name"] = system.name if system is not None else None
    return rep


def _infer_code(spec: str, opts: InferOptions) -> dict:
    """The search on ``--callable``/``--decoder`` code, run in a child process with ``opts.timeout``."""
    from ...io.transaction import note_input  # lazy: the spawned child loads this package, and needs no I/O layer

    path = code_file(spec)
    if path is not None:
        note_input(path)  # -o/--json may never be the user's own code
    rep, toml, system_name = run_code_inference(
        spec,
        builder=opts.builder,
        roles=list(opts.roles),
        units="degrees" if opts.units == "deg" else "radians",
        packed=opts.packed,
        samples=opts.samples,
        timeout=DEFAULT_TIMEOUT if opts.timeout is None else opts.timeout,
        tol=opts.tol or inf.CODE_TOL,
        seed=opts.seed,
        source=spec,
        name=opts.name,
        frame=opts.frame,
        storage=opts.storage,
        import_path=list(opts.import_path),
        returns=opts.returns,
        threads=opts.threads,
    )
    if rep["fit"] != "exact" and opts.units is None and opts.returns == "angles":
        rep["hint"] = "no fit with the default --radians; try --degrees"
    rep["_system_toml"], rep["_system_name"] = toml, system_name
    return rep
