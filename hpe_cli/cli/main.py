"""The ``hpe`` command group. Subcommands are imported only when used, so ``hpe --help`` stays fast."""

from __future__ import annotations

import importlib
import importlib.util
import os

import click

from .version import version_option

#: command name -> "module:function". One module per command.
COMMANDS = {
    "convert": "hpe_cli.cli.convert:convert",
    "systems": "hpe_cli.cli.systems:systems",
    "relabel-panoptic": "hpe_cli.cli.relabel_panoptic:relabel_panoptic",
    "relabel-agora": "hpe_cli.cli.relabel_agora:relabel_agora",
    "audit": "hpe_cli.cli.audit:audit",
    "draw": "hpe_cli.cli.draw:draw",
    "augment": "hpe_cli.cli.augment:augment",
    "infer": "hpe_cli.cli.infer:infer",
    "biwi": "hpe_cli.cli.biwi:biwi",
    "evaluate": "hpe_cli.cli.evaluate:evaluate",
    "export": "hpe_cli.cli.export:export",
    "view": "hpe_cli.cli.view:view",
}


class HpeGroup(click.Group):
    """Lazy subcommands, each run inside one output transaction; failures become one line on stderr.

    Exit codes: 0 success, 1 a failure the user can act on (bad input, OS error,
    rejected rows), 2 usage, 128+N on signal N (SIGINT, SIGTERM, SIGHUP), after
    removing every staged output and stopping worker processes.
    """

    def make_context(self, info_name, args, parent=None, **extra):
        """``hpe --bogus``: the group's own usage errors are one line too (exit 2); no arguments shows the help."""
        try:
            return super().make_context(info_name, args, parent=parent, **extra)
        except click.UsageError as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":
                raise
            _error(f"{exc.format_message()} (see 'hpe --help')")
            raise SystemExit(2) from None

    def resolve_command(self, ctx, args):
        """``hpe convrt``: the unknown command's error names the command the user most likely meant."""
        name = args[0] if args else ""
        if name and not name.startswith("-") and self.get_command(ctx, name) is None:
            from .suggest import did_you_mean

            hint = did_you_mean(name, self.list_commands(ctx)) or " (see 'hpe --help' for the commands)"
            ctx.fail(f"No such command {name!r}{hint}.")
        return super().resolve_command(ctx, args)

    def list_commands(self, ctx):
        return [n for n, target in COMMANDS.items() if importlib.util.find_spec(target.split(":")[0])]

    def get_command(self, ctx, name):
        target = COMMANDS.get(name)
        if target is None:
            return None
        module, attr = target.split(":")
        if importlib.util.find_spec(module) is None:
            return None
        from .options import mark_paths

        return mark_paths(getattr(importlib.import_module(module), attr))

    def invoke(self, ctx):
        import warnings

        from ..io.system_meta import end_run, start_run
        from ..io.transaction import OutputTransaction
        from . import signals
        from .plugins import load_plugins

        txn = OutputTransaction()
        run_token = start_run()
        try:
            with warnings.catch_warnings(), signals.handled():
                if not os.environ.get("HPE_DEBUG"):
                    warnings.simplefilter("ignore")  # numpy/pandas warnings name internal paths
                with txn.activate(run=True):
                    load_plugins()  # HPE_PLUGINS: user files that register readers, layouts, protocols...
                    return super().invoke(ctx)
        except click.UsageError as exc:  # one line, exit 2 (click's own form is usage + hint + error)
            if signals.fired() is None:
                where = exc.ctx.command_path.split()[-1] if exc.ctx is not None else ""
                hint = f" (see 'hpe {where} --help')" if exc.ctx is not None and exc.ctx.parent is not None else ""
                _error(exc.format_message() + hint)
                ctx.exit(2)
            raise
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
            if signals.fired() is not None:
                exc = signals.fired()
                signals.stop_children()
                _error(f"interrupted ({exc.name})")
                ctx.exit(128 + exc.signum)
            raise
        except signals.Interrupted as exc:
            signals.stop_children()
            _error(f"interrupted ({exc.name})")
            ctx.exit(128 + exc.signum)
        except KeyboardInterrupt:
            signals.stop_children()
            _error("interrupted (SIGINT)")
            ctx.exit(130)
        except BrokenPipeError:  # e.g. `hpe systems | head`: the reader left, nothing to report
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            ctx.exit(1)
        except Exception as exc:
            if signals.fired() is not None:  # e.g. a worker pool broken by the signal: report the signal
                stop = signals.fired()
                signals.stop_children()
                _error(f"interrupted ({stop.name})")
                ctx.exit(128 + stop.signum)
            msg = _message(exc, txn)
            if msg is None:  # a bug: never show a traceback unless asked to
                if os.environ.get("HPE_DEBUG"):
                    raise
                msg = (
                    f"internal error {type(exc).__name__}: {' '.join(str(exc).split())[:300]} "
                    "(please report it; set HPE_DEBUG=1 for a traceback)"
                )
            _error(msg)
            from ..errors import HpeError

            ctx.exit(exc.exit_code if isinstance(exc, HpeError) else 1)
        finally:
            end_run(run_token)


def _message(exc, txn=None) -> str | None:
    """The one-line message of an error a user can provoke, or None for a bug."""
    from ..errors import HpeError
    from ..io.transaction import os_reason
    from ..rotation.systems import SystemError_

    if isinstance(exc, (HpeError, SystemError_)):
        return str(exc)
    if isinstance(exc, MemoryError):
        return "out of memory (try a smaller --batch-size)"
    if isinstance(exc, OSError):
        name = exc.filename if exc.filename is not None else None
        return f"{name}: {os_reason(exc)}" if name is not None else os_reason(exc)
    if isinstance(exc, UnicodeEncodeError) and "surrogate" in str(exc):
        bad = [p for p in (txn.paths() if txn is not None else []) if not _utf8(p)]
        if bad:
            return f"{bad[0]}: file name is not valid UTF-8, which this reader cannot open (rename the file)"
        return "a file name is not valid UTF-8, which this reader cannot open (rename the file)"
    inputs = txn.input_paths() if txn is not None else []
    if isinstance(exc, UnicodeDecodeError):
        where = f"{inputs[0]}: " if len(inputs) == 1 else ""
        return f"{where}text is not valid UTF-8 (byte {exc.start}: {exc.reason})"
    if isinstance(exc, UnicodeError):
        return f"text is not valid UTF-8 ({exc.reason})" if hasattr(exc, "reason") else str(exc)
    if len(inputs) == 1 and type(exc).__module__.split(".")[0] in _READER_MODULES:
        # a reader library's own error while the run read its one input: name that file
        return f"{inputs[0]}: cannot read: {' '.join(str(exc).split())[:200]}"
    return None


#: libraries whose errors, in a run with one input, come from reading that input
_READER_MODULES = {
    "pyarrow",
    "pandas",
    "scipy",
    "json",
    "orjson",
    "pickle",
    "_pickle",
    "tarfile",
    "zipfile",
    "gzip",
    "zlib",
    "h5py",
    "numpy",
}


def _utf8(path) -> bool:
    try:
        str(path).encode("utf-8")
        return True
    except UnicodeEncodeError:
        return False


def _error(msg: str) -> None:
    from ..io.transaction import printable
    from . import signals

    if msg.startswith("interrupted ("):
        signals.reported = True
    click.echo(f"Error: {printable(' '.join(str(msg).split()))}", err=True)


@click.group(cls=HpeGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@version_option  # the version and the optional parts installed (cli/version.py)
def cli():
    """hpe: relabel head-pose datasets correctly.

    Every label has a rotation system (frame, axes and handedness, range,
    order). hpe converts between systems exactly, relabels Panoptic and AGORA
    from 3-D landmarks, audits, draws and augments labels, and infers the
    system a piece of code or data uses.

    \b
    Examples:
      hpe systems
      hpe convert labels.csv -o labels_6d.parquet --from 300w_lp --to 6drepnet
      hpe convert AFLW2000/ -o aflw.parquet --from 300w_lp --to whenet
      hpe relabel-panoptic sample_data/panoptic_160906_pizza1 -o labels.parquet
      hpe audit labels.parquet --system 300w_lp --json report.json
    """


def main():
    """Entry point (``hpe``, ``python -m hpe_cli``): run the command, then :func:`clean_exit` with its status."""
    try:
        cli(prog_name="hpe")
        code = 0
    except SystemExit as exc:
        code = exc.code
    clean_exit(code)


def clean_exit(code) -> None:
    """End the process with ``code`` without tearing down native thread pools.

    Arrow's CPU and I/O pools (started by any threaded CSV/Parquet read) are
    process-wide C++ objects that Python cannot join. A process that exits
    through the C runtime while one of their threads is still starting (an
    early error right after a read, on a loaded machine) runs their static
    destructors on a joinable ``std::thread``: ``terminate called without an
    active exception``, exit 134 (apache/arrow#34314, #39862). So: wait for
    hpe's own non-daemon threads (background writers), run the ``atexit``
    handlers (executor and multiprocessing shutdown), flush stdout/stderr,
    and leave with ``os._exit`` -- the exit status is always the command's.
    """
    import atexit
    import sys
    import threading

    if code is None:
        code = 0
    elif not isinstance(code, int):
        print(code, file=sys.stderr)
        code = 1
    for t in threading.enumerate():
        if t is not threading.current_thread() and not t.daemon:
            t.join(timeout=30)
    import contextlib

    with contextlib.suppress(Exception):  # a handler's failure must not change the status
        atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (`hpe systems | head`)
            pass
    os._exit(code)


if __name__ == "__main__":
    main()
