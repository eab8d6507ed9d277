"""``hpe infer --callable/--decoder``: run the user's code in a child process with a time limit.

The user's module is imported and called in a fresh interpreter
(``multiprocessing`` with the ``spawn`` start method), so nothing it does can
end, hang or change ``hpe`` itself: a hang past ``timeout`` seconds, a
``sys.exit(n)``, an ``os._exit``, a crash (signal), closed file descriptors or an
exception becomes one :class:`~hpe_cli.errors.HpeError` line, and the command
exits 1. The child sends back the JSON report and, for an exact fit, the matched
system as TOML (the same objects the in-process search gives).

The child leads its own process group; when the search ends (answer, error or
timeout) the whole group is killed, so processes the code forked or started
(``subprocess.Popen(["sleep", "3600"])``) do not outlive ``hpe``. (A process that
leaves the group on purpose, ``setsid``, is beyond this.)
"""

from __future__ import annotations

import importlib
import importlib.util
import multiprocessing as mp
import os
import re
import signal
import sys
import warnings
from pathlib import Path

from ...errors import HpeError
from ...rotation import infer as inf
from ..pools import default_threads

DEFAULT_TIMEOUT = 60.0
#: exit status of the child when the code closed the pipe it answers on (its file descriptors)
_NO_CHANNEL = 86


def _child(conn, spec, builder, roles, units, packed, samples, kw):
    """Runs in the child: load, search, send ``("ok", report, toml, name)`` or ``("error", message)``."""
    if not os.environ.get("HPE_DEBUG"):
        warnings.simplefilter("ignore")  # as in the parent: no library warnings with internal paths
    if hasattr(os, "setpgid"):
        os.setpgid(0, 0)  # a process group of our own: the parent ends it with everything the code starts
    conn.send(("ready",))  # hpe itself is loaded: the time limit starts now
    code_threads(kw.pop("threads", None))
    try:
        func = load_callable(spec, kw.pop("import_path", None))
        returns = kw.pop("returns", "angles")
        if returns != "angles":  # a decoder returning a rotation vector, quaternion, 6-D vector or matrix
            rep = inf.infer_storage_decoder(inf.as_value_decoder(func), n=samples or 256, **kw)
        elif builder:
            rep = inf.infer_builder(inf.as_builder(func, roles, units, packed), n=samples or 64, **kw)
        else:
            rep = inf.infer_decoder(inf.as_decoder(func, roles, units), n=samples or 256, **kw)
        system = rep.get("_system")
        msg = (
            "ok",
            inf.report_json(rep),
            system.to_toml() if system is not None else None,
            system.name if system is not None else None,
        )
    except HpeError as exc:
        msg = ("error", str(exc))
    except inf.CallError as exc:
        msg = ("error", f"{spec}: {exc}")
    except SystemExit as exc:
        msg = ("error", f"{spec}: the code called sys.exit({exc.code!r})")
    except BaseException as exc:  # noqa: BLE001 - the user's code may raise anything
        msg = ("error", f"{spec}: raised {type(exc).__name__}: {' '.join(str(exc).split())[:200]}")
    status = 0
    try:
        try:
            conn.send(msg)
        except (OSError, EOFError):
            raise
        except Exception as exc:  # noqa: BLE001 - e.g. an unpicklable value in the report
            conn.send(("error", f"{spec}: cannot return the result ({type(exc).__name__})"))
        conn.close()
    except BaseException:  # noqa: BLE001 - the code closed or replaced our pipe: no traceback, a status
        status = _NO_CHANNEL
    try:
        sys.stdout.flush()
    except BaseException:  # noqa: BLE001, S110 - stdout closed by the code
        pass
    os._exit(status)  # skip the user's atexit handlers and non-daemon threads


#: the variables the thread pools of torch, MKL, OpenBLAS and OpenMP code read when they start
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def code_threads(threads=None) -> None:
    """Set :data:`THREAD_VARIABLES` in this (child) process before the user's code is imported: to ``threads``
    when given (``--threads``), else to :func:`~hpe_cli.pipelines.pools.default_threads` where not already set."""
    n = str(default_threads(threads))
    for var in THREAD_VARIABLES:
        if threads is not None:
            os.environ[var] = n
        else:
            os.environ.setdefault(var, n)


def run_code_inference(
    spec: str,
    *,
    builder: bool,
    roles,
    units: str,
    packed: bool = False,
    samples=None,
    timeout: float = DEFAULT_TIMEOUT,
    **kw,
) -> tuple:
    """Run the search on ``spec`` (``FILE.py:FUNC`` or ``module:FUNC``) in a child process.

    Returns ``(report, system_toml, system_name)``: the JSON report of
    :func:`hpe_cli.rotation.infer.infer_builder` (``builder=True``) or
    :func:`~hpe_cli.rotation.infer.infer_decoder`, and the matched system as
    TOML text and name (None when nothing fits exactly).

    Raises
    ------
    HpeError
        The code could not be loaded, raised, exited, crashed, or ran longer
        than ``timeout`` seconds.
    """
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(
        target=_child,
        args=(send, spec, builder, roles, units, packed, samples, kw),
        daemon=True,
        name="hpe-infer-user-code",
    )
    proc.start()
    send.close()
    ready = False
    try:
        # the child first loads Python, numpy and hpe (not the user's time), then says "ready"
        ready = recv.poll(max(120.0, timeout))
        if ready:
            try:
                recv.recv()
            except Exception:  # noqa: BLE001 - EOF, a closed pipe or garbage: no answer
                ready = False
        got = recv.poll(timeout) if ready else True
        msg = None
        if got:
            try:
                msg = recv.recv()
            except Exception:  # noqa: BLE001 - as above
                msg = None
        if not (isinstance(msg, tuple) and msg and msg[0] in ("ok", "error")):
            msg = None
        if msg is None:
            if proc.is_alive() and not got:
                _end_group(proc, ready)
                raise HpeError(f"{spec}: no answer within --timeout {timeout:g} s (the code hangs or is too slow)")
            proc.join(5)
            code = proc.exitcode
            if code == _NO_CHANNEL:
                raise HpeError(
                    f"{spec}: the code closed the pipe hpe reads its answer from (it closes file "
                    "descriptors it did not open), so it returned nothing"
                )
            if code is not None and code < 0:
                try:
                    name = signal.Signals(-code).name
                except ValueError:
                    name = f"signal {-code}"
                raise HpeError(f"{spec}: the code crashed ({name})")
            raise HpeError(f"{spec}: the code ended the process (exit status {code}) before returning")
        if msg[0] == "error":
            raise HpeError(msg[1])
        return msg[1], msg[2], msg[3]
    finally:
        recv.close()
        _end_group(proc, ready)


def code_file(spec: str):
    """The ``.py`` file of ``FILE.py:FUNC``, or None for ``module.path:FUNC``."""
    target = spec.rpartition(":")[0]
    if target and (target.endswith(".py") or Path(target).is_file()):
        return Path(target)
    return None


def _end_group(proc, grouped: bool) -> None:
    """Kill the child's process group (the child and everything it started), then reap the child.

    ``grouped``: the child said "ready", so it had made its own group (its id is the child's pid).
    """
    if grouped and proc.pid is not None and hasattr(os, "killpg"):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    if proc.is_alive():
        proc.kill()
    proc.join(2)


def module_name_of(path):
    """``(root, "pkg.sub.mod")`` for a file inside a package, else None.

    Walks up the folders that hold an ``__init__.py``; a folder without one is
    still taken as a (namespace) package when the file uses relative imports
    (3DDFA_V2's ``utils/pose.py`` does ``from .functions import ...`` and
    ``utils/`` has no ``__init__.py``).
    """
    path = path.resolve()
    parts, folder = [], path.parent
    while (folder / "__init__.py").is_file() and folder.parent != folder:
        parts.insert(0, folder.name)
        folder = folder.parent
    if not parts:
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return None
        if not re.search(r"^\s*from\s+\.", text, re.MULTILINE):
            return None
        parts, folder = [path.parent.name], path.parent.parent
    if not all(p.isidentifier() for p in parts) or not path.stem.isidentifier():
        return None
    return folder, ".".join(parts + [path.stem])


def load_callable(spec: str, path=None):
    """``path/to/file.py:func`` or ``package.module:func`` (``func`` may be ``Class.method``).

    A file inside a package is imported as that package's module (so its
    relative imports work); ``path`` (folders) is put on ``sys.path`` first,
    for ``package.module:func`` specs that live outside the installed packages.
    """
    target, sep, attr = spec.rpartition(":")
    if not sep or not target or not attr:
        raise HpeError(f"{spec}: expected FILE.py:FUNC or module.path:FUNC")
    for root in reversed([str(Path(p).resolve()) for p in (path or ())]):
        if root not in sys.path:
            sys.path.insert(0, root)
    file = Path(target)
    try:
        if target.endswith(".py") or file.exists():
            if not file.is_file():
                raise HpeError(f"{target}: no such file")
            found = module_name_of(file)
            top = found[1].split(".")[0] if found else None
            if found is not None and (
                top not in sys.modules or str(found[0]) in str(getattr(sys.modules[top], "__path__", ""))
            ):
                root, dotted = found
                for folder in (str(root), str(file.resolve().parent)):
                    if folder not in sys.path:
                        sys.path.insert(0, folder)  # the package root, and the file's siblings
                module = importlib.import_module(dotted)
            else:
                name = f"_hpe_infer_{abs(hash(str(file.resolve())))}"
                mod_spec = importlib.util.spec_from_file_location(name, file)
                module = importlib.util.module_from_spec(mod_spec)
                sys.modules[name] = module  # dataclasses and pickling look their module up here
                folder = str(file.resolve().parent)
                sys.path.insert(0, folder)  # let the file import its siblings
                try:
                    mod_spec.loader.exec_module(module)
                finally:
                    if folder in sys.path:
                        sys.path.remove(folder)
        else:
            module = importlib.import_module(target)
    except HpeError:
        raise
    except Exception as exc:  # noqa: BLE001 - the user's module may raise anything on import
        hint = ""
        if "relative import" in str(exc):
            hint = " (the file is not inside a package: give module:FUNC with --path ROOT)"
        raise HpeError(
            f"{target}: import failed: {type(exc).__name__}: {' '.join(str(exc).split())[:200]}{hint}"
        ) from None
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise HpeError(f"{target}: has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise HpeError(f"{spec}: expected a callable, got {type(obj).__name__}")
    return obj
