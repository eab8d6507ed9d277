"""The output transaction: all outputs of one run are committed together, or none is.

Every writer (:class:`~hpe_cli.io.writers.AtomicFile`, ``TableWriter``,
``write_table``, ``write_json``, ``Rejects.write``, the audit plots, and folders
from :func:`staged_dir`) stages its output as a temporary file or folder named
``.hpe-<8 hex>.tmp`` next to the target. The run's transaction (opened by the
``hpe`` group around every command, or by :func:`ensure_transaction` in library
code) commits all staged outputs at the end of the run, or removes them all on
an error, ``sys.exit``, or a signal.

Rules enforced here, for every command:

- an output that resolves (``os.path.realpath``, or the same inode when the
  file exists) to an input of the run, or to another output of the same run,
  is refused, with or without ``--overwrite``;
- a new file is created without overwriting atomically (``os.link`` of the
  staged file, which fails if the name exists), so two concurrent runs cannot
  both create one output;
- an overwritten file keeps its permission bits; a new file gets the mode a
  plain ``open()`` would give it (the umask applies; the umask is never set);
- errors name the user's path and the reason (permission denied, read-only
  file system, disk full, name too long), never a temporary name.
- a staged folder whose target does not exist yet, with at least
  :data:`RENAME_MIN_FILES` files and no input of the run under it, is placed
  whole: its name is claimed with ``mkdir`` (fails if anything took it) and
  the staged folder renamed onto that empty folder (``rename(2)`` replaces an
  empty folder atomically); undone by renaming it back. A race (the name taken,
  a file put into it meanwhile) falls back to placing the files one by one,
  with every check of that path;
- a file given to :meth:`OutputTransaction.remove_at_commit` (a stale file of
  an earlier output folder) is removed as part of the commit, after every
  output is placed: renamed to a temp next to it, and renamed back if the
  commit fails; an input of the run is never removed;
- a commit that fails halfway (a target name taken by a folder meanwhile, a
  read-only folder, a full disk) undoes the files already placed: new ones are
  removed, replaced ones restored from hard-link backups;
- a signal before the commit removes everything staged (exit 128+N); once the
  run's transaction has committed, a signal no longer undoes anything: the run
  ends normally and says it is complete (``cli/signals.py``);
- each staged temp is ``flock``-ed while its run lives, so a later run staging
  into the same folder removes the temps of runs that were killed (``kill -9``)
  once they are :data:`~hpe_cli.io.stale_temps.SWEEP_AGE` seconds old
  (:mod:`hpe_cli.io.stale_temps`).

Without a transaction, each writer commits its own output atomically.
"""

from __future__ import annotations

import contextvars
import os
from contextlib import contextmanager
from pathlib import Path

from ..errors import HpeError
from . import os_errors
from .os_errors import os_reason, printable
from .placement import count_files, place_file, remove_path, rename_dir, temp_in, unplace_file
from .stale_temps import SWEEP_AGE, lock_file, sweep_stale_temps  # noqa: F401 - SWEEP_AGE for tests

__all__ = [
    "OutputTransaction",
    "current",
    "ensure_transaction",
    "staged_dir",
    "note_input",
    "os_reason",
    "printable",
    "TEMP_PREFIX",
]

TEMP_PREFIX = os_errors.TEMP_PREFIX
#: a staged folder with at least this many files (and a target that does not exist) is renamed into place whole;
#: smaller ones are placed file by file (the cost is the same, and the per-file path is the one fault tests probe)
RENAME_MIN_FILES = 256
_current: contextvars.ContextVar = contextvars.ContextVar("hpe_output_transaction", default=None)
#: the run's transaction, also visible from worker threads (which do not inherit context variables)
_run = None
#: set by a signal handler: no transaction may commit any more (the exception to raise instead)
_stop = None


def request_stop(exc: BaseException | None) -> None:
    """From a signal handler: make every later commit raise ``exc`` (None clears it)."""
    global _stop
    _stop = exc


def stop_requested() -> BaseException | None:
    return _stop


#: True once the run's transaction (the one opened by the ``hpe`` group) has committed: from then on the
#: run's outputs are complete, and a signal no longer undoes anything (cli/signals.py says so instead)
_run_committed = False


def run_committed() -> bool:
    return _run_committed


def reset_run_state() -> None:
    """At the start of a run: no signal received, nothing committed."""
    global _stop, _run_committed
    _stop = None
    _run_committed = False


_critical = 0
_pending = None


def critical():
    """A block no signal exception interrupts: one arriving inside it is raised when it ends.

    Use it around creating a file or folder and recording it for cleanup.
    """
    return _section()


def in_critical_section(exc: BaseException) -> bool:
    """From a signal handler: if a file operation and its bookkeeping are under way, hold ``exc`` back
    (it is raised as soon as the section ends) and return True."""
    global _pending
    if _critical:
        _pending = exc
        return True
    return False


_late_signal = None  # called instead of raising a signal held back until the run had committed


def on_late_signal(func) -> None:
    """What a signal held back until the run's commit finished does (``cli/signals.py``: the run is complete)."""
    global _late_signal
    _late_signal = func


@contextmanager
def _section():
    """Create/rename a file and record it, with no signal exception in between."""
    global _critical, _pending
    _critical += 1
    try:
        yield
    finally:
        _critical -= 1
        if not _critical and _pending is not None:
            exc, _pending = _pending, None
            if _run_committed and _late_signal is not None:  # the outputs are complete: nothing to undo
                _late_signal(exc)
            else:
                raise exc


def _real(path) -> str:
    return os.path.realpath(os.fspath(path))


def _key(path):
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino)


def _name_max(folder: Path) -> int:
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


class _Item:
    """One path of the run: an input, a declared output or a staged output."""

    __slots__ = ("shown", "real", "key", "label")

    def __init__(self, path, label: str = ""):
        self.label = label
        self.shown = os.fspath(path)
        self.real = _real(path)
        self.key = _key(path)

    def same(self, other: "_Item") -> bool:
        return self.real == other.real or (self.key is not None and self.key == other.key)


class _Staged:
    __slots__ = ("target", "tmp", "overwrite", "is_dir", "item", "lock")

    def __init__(self, target: Path, tmp: Path, overwrite: bool, is_dir: bool, lock=None):
        self.target, self.tmp, self.overwrite, self.is_dir = target, tmp, overwrite, is_dir
        self.item = _Item(target)
        self.lock = lock  # a descriptor holding flock on the temp while this run lives (see sweep_stale_temps)

    def release(self) -> None:
        if self.lock is not None:
            try:
                os.close(self.lock)
            except OSError:
                pass
            self.lock = None


class OutputTransaction:
    """All outputs of one run: staged next to their targets, committed together or removed.

    Use :meth:`activate` (a context manager) to make it the current transaction:
    writers then stage into it; it commits when the block ends normally and
    aborts (removes everything staged) on any exception, ``SystemExit`` and
    ``KeyboardInterrupt`` included.
    """

    def __init__(self):
        self._inputs: list = []
        self._outputs: list = []  # declared outputs (command-line parameters)
        self._staged: list = []
        self._made_dirs: list = []  # folders created for outputs, removed on abort if still empty
        self._removals: list = []  # files removed at commit (stale files of an earlier output folder)
        self._after: list = []
        self._on_abort: list = []
        self._swept: set = set()
        self.state = "open"

    # ------------------------------------------------------------- declarations
    def add_input(self, path, label: str = "") -> None:
        """Declare an input of the run (``label``: its option name): no output may resolve to it."""
        if path is None or os.fspath(path) == "-":
            return
        item = _Item(path, label)
        for out in self._outputs + [s.item for s in self._staged]:
            if out.same(item):
                raise HpeError(_collision(out, item, "input"))
        self._inputs.append(item)

    def add_output(self, path, label: str = "") -> None:
        """Declare an output of the run: it may be neither an input nor another declared output."""
        if path is None or os.fspath(path) == "-":
            return
        item = _Item(path, label)
        self._check_inputs(item)
        for out in self._outputs:
            if out.same(item):
                raise HpeError(_collision(item, out, "output"))
        self._outputs.append(item)

    def _check_inputs(self, item: _Item) -> None:
        for inp in self._inputs:
            if inp.same(item):
                raise HpeError(_collision(item, inp, "input"))

    def input_paths(self) -> list:
        """The run's inputs, as given."""
        return [i.shown for i in self._inputs]

    def paths(self) -> list:
        """Every input and output path of the run, as given (for error messages)."""
        return [i.shown for i in self._inputs + self._outputs] + [os.fspath(s.target) for s in self._staged]

    def remove_at_commit(self, path) -> None:
        """Remove file ``path`` when the run commits, as part of it (restored if the commit fails); it may not be
        an input of the run."""
        item = _Item(path)
        self._check_inputs(item)
        self._removals.append(Path(path))

    def on_abort(self, func) -> None:
        """Call ``func()`` if the run aborts (e.g. remove a work folder that is not an output)."""
        self._on_abort.append(func)

    def after_commit(self, func) -> None:
        """Call ``func()`` once everything is committed (e.g. print the summary)."""
        self._after.append(func)

    # ------------------------------------------------------------------ staging
    def _prepare(self, path, overwrite: bool, is_dir: bool) -> tuple:
        if self.state != "open":
            raise HpeError(f"{path}: the run's outputs are already {self.state}")
        path = Path(path)
        item = _Item(path)
        self._check_inputs(item)
        for s in self._staged:
            if s.item.same(item):
                raise HpeError(_collision(item, s.item, "output"))
        if path.is_dir() and not is_dir:
            raise HpeError(f"{path}: is a folder, expected a file name")
        if path.exists() and not path.is_dir() and is_dir:
            raise HpeError(f"{path}: is a file, expected a folder")
        if path.exists() and not overwrite and not is_dir:
            raise HpeError(f"{path}: already exists (use --overwrite to replace it)")
        parent = path.parent
        with _section():
            self._make_parents(path, parent)
        key = _real(parent)
        if key not in self._swept:  # a killed run's temps in this folder go now
            self._swept.add(key)
            sweep_stale_temps(parent, {s.tmp for s in self._staged})
        if len(os.fsencode(path.name)) > _name_max(parent):
            raise HpeError(f"{path}: file name too long")
        return path, parent

    def _make_parents(self, path: Path, parent: Path) -> None:
        missing = []
        p = parent
        while not p.exists():
            if p.is_symlink():  # a dangling link
                raise HpeError(f"{path}: folder {p} is a broken symbolic link")
            missing.append(p)
            if p.parent == p:
                break
            p = p.parent
        if p.exists() and not p.is_dir():
            raise HpeError(f"{path}: {p} is not a folder")
        for d in reversed(missing):
            try:
                d.mkdir()
            except FileExistsError:
                continue
            except OSError as exc:
                raise HpeError(f"{path}: cannot create folder {d}: {os_reason(exc)}") from None
            self._made_dirs.append(d)

    def stage_file(self, path, overwrite: bool = False) -> Path:
        """Reserve ``path`` as an output; return the temporary file to write instead."""
        path, parent = self._prepare(path, overwrite, is_dir=False)
        for _ in range(16):
            tmp = temp_in(parent)
            with _section():
                try:
                    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
                except FileExistsError:
                    continue
                except OSError as exc:
                    raise HpeError(f"{path}: cannot write: {os_reason(exc)}") from None
                lock_file(fd)
                self._staged.append(_Staged(path, tmp, overwrite, False, fd))
            return tmp
        raise HpeError(f"{path}: cannot create a temporary file in {parent}")

    def stage_dir(self, path, overwrite: bool = False) -> Path:
        """Reserve folder ``path`` as an output; return the temporary folder to fill instead.

        At commit its files are moved into ``path`` (created if missing); an
        existing file there is replaced only with ``overwrite``.
        """
        path, parent = self._prepare(path, overwrite, is_dir=True)
        for _ in range(16):
            tmp = temp_in(parent)
            with _section():
                try:
                    os.mkdir(tmp, 0o777)
                except FileExistsError:
                    continue
                except OSError as exc:
                    raise HpeError(f"{path}: cannot write: {os_reason(exc)}") from None
                try:
                    fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
                    lock_file(fd)
                except OSError:
                    fd = None
                self._staged.append(_Staged(path, tmp, overwrite, True, fd))
            return tmp
        raise HpeError(f"{path}: cannot create a temporary folder in {parent}")

    def discard(self, tmp) -> None:
        """Forget a staged output and remove its temporary file or folder."""
        for s in list(self._staged):
            if s.tmp == Path(tmp):
                self._staged.remove(s)
                remove_path(s.tmp)
                s.release()

    def staged_temps(self) -> list:
        """The temporary files and folders staged so far (to be removed by a later run if this one is killed)."""
        return [s.tmp for s in self._staged]

    def target_of(self, tmp) -> Path | None:
        for s in self._staged:
            if s.tmp == Path(tmp):
                return s.target
        return None

    # ------------------------------------------------------------ commit/abort
    def _dir_plan(self, s: _Staged) -> list:
        """(tmp file, target file) pairs of a staged folder, after checking each target."""
        pairs = []
        for root, dirs, files in os.walk(s.tmp):
            dirs.sort()
            for f in sorted(files):
                src = Path(root) / f
                dst = s.target / src.relative_to(s.tmp)
                item = _Item(dst)
                self._check_inputs(item)
                if dst.is_dir():
                    raise HpeError(f"{dst}: is a folder, expected a file name")
                if dst.exists() and not s.overwrite:
                    raise HpeError(f"{dst}: already exists (use --overwrite to replace it)")
                pairs.append((src, dst))
        return pairs

    def _can_rename(self, s: _Staged) -> bool:
        """Whether staged folder ``s`` may be placed whole (:func:`rename_dir`): its target does not exist, no
        input of the run lies under it, and it holds at least :data:`RENAME_MIN_FILES` files."""
        if os.path.lexists(s.target):
            return False
        real = _real(s.target)
        under = real.rstrip(os.sep) + os.sep
        if any(i.real == real or i.real.startswith(under) for i in self._inputs):
            return False
        return count_files(s.tmp, RENAME_MIN_FILES) >= RENAME_MIN_FILES

    def commit(self) -> None:
        """Move every staged output into place; on any failure undo what was moved and remove the rest."""
        if self.state != "open":
            return
        if _stop is not None:  # a signal arrived (even if something swallowed its exception): commit nothing
            self.abort()
            raise _stop
        self.state = "committing"
        undo: list = []
        backups: list = []
        with _section():  # a signal is held until every output is placed and recorded, or all are undone
            self._commit(undo, backups)
        for func in self._after:
            func()

    def _commit(self, undo: list, backups: list) -> None:
        global _run_committed
        try:
            plans = []
            for s in self._staged:
                if s.is_dir:
                    plans.append((s, None if self._can_rename(s) else self._dir_plan(s)))
                else:
                    self._check_inputs(s.item)
                    if s.target.exists() and not s.overwrite:
                        raise HpeError(
                            f"{s.target}: already exists (another run created it meanwhile; "
                            "use --overwrite to replace it)"
                        )
                    plans.append((s, [(s.tmp, s.target)]))
            for s, pairs in plans:
                if pairs is None:  # a new folder: placed whole, or (a race) file by file after all
                    with _section():
                        if rename_dir(s, self._make_parents, undo):
                            continue
                    pairs = self._dir_plan(s)
                if s.is_dir:
                    with _section():
                        self._make_parents(s.target / "x", s.target)
                for src, dst in pairs:
                    with _section():
                        if s.is_dir:
                            self._make_parents(dst, dst.parent)
                        place_file(src, dst, s.overwrite, undo, backups)
            for p in self._removals:
                with _section():
                    unplace_file(p, undo, backups)
        except BaseException as exc:
            for action in reversed(undo):
                try:
                    action()
                except OSError:
                    pass
            self.state = "open"
            self.abort()
            if isinstance(exc, OSError):
                raise HpeError(f"{getattr(exc, 'hpe_target', '')}: cannot write: {os_reason(exc)}") from None
            raise
        for b in backups:
            remove_path(b)
        for s in self._staged:
            if s.is_dir:
                remove_path(s.tmp)
            s.release()
        self._staged.clear()
        self._made_dirs.clear()
        self._removals.clear()
        self.state = "committed"
        if self is _run:
            _run_committed = True

    def abort(self) -> None:
        """Remove everything staged and every folder created for it (if still empty)."""
        if self.state in ("aborted", "committed"):
            return
        self.state = "aborted"
        for func in self._on_abort:
            try:
                func()
            except Exception:  # noqa: BLE001 - cleanup is best effort
                pass
        for s in self._staged:
            remove_path(s.tmp)
            s.release()
        self._staged.clear()
        for d in reversed(self._made_dirs):
            try:
                d.rmdir()
            except OSError:
                pass
        self._made_dirs.clear()
        self._removals.clear()

    # ------------------------------------------------------------------ scope
    @contextmanager
    def activate(self, run: bool = False):
        """Make this the current transaction; commit at the end, abort on any exception."""
        global _run
        token = _current.set(self)
        previous = _run
        if run:
            _run = self
        try:
            yield self
            self.commit()
        except BaseException as exc:
            if getattr(exc, "keep", None) and self.state == "open" and _stop is None:  # errors.RejectedAllError
                self.commit()  # what is still staged: the rejects file (io.rejects.fail_all_rejected)
            self.abort()
            raise
        finally:
            _current.reset(token)
            if run:
                _run = previous


def _collision(out: _Item, other: _Item, kind: str) -> str:
    what = out.label or "the output"
    against = f"{other.label} {other.shown}" if other.label else f"the {kind} {other.shown}"
    return (
        f"{out.shown}: {what} must differ from {against} (the same file after links); "
        "refusing to write it, with or without --overwrite"
    )


def active_transaction() -> OutputTransaction | None:
    """The run's transaction, else the context's, whatever its state (the signal watchdog aborts it)."""
    return _run or _current.get()


def current() -> OutputTransaction | None:
    """The transaction outputs are staged into now (None in plain library use)."""
    txn = _current.get()
    if txn is None:
        txn = _run
    return txn if txn is not None and txn.state == "open" else None


@contextmanager
def ensure_transaction():
    """Join the current transaction, or open one committed when this block ends."""
    txn = current()
    if txn is not None:
        yield txn
        return
    txn = OutputTransaction()
    with txn.activate():
        yield txn


def note_input(path) -> None:
    """Declare ``path`` an input of the current run (no-op without a transaction)."""
    txn = current()
    if txn is not None:
        txn.add_input(path)


@contextmanager
def staged_dir(path, overwrite: bool = False):
    """A temporary folder whose files are moved into folder ``path`` when the run commits.

    Without a current transaction the folder is committed when the block ends.
    Nothing appears in ``path`` before the commit; on failure nothing does.
    """
    with ensure_transaction() as txn:
        tmp = txn.stage_dir(path, overwrite)
        try:
            yield tmp
        except BaseException:
            txn.discard(tmp)
            raise
