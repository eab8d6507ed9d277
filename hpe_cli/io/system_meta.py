"""Which rotation system a label table's labels are in: the ONE place every command and the API decide it.

The rule
--------
A file that names its system is read in that system: a Parquet file's
``hpe:system_definition`` / ``hpe:system`` metadata (every Parquet file ``hpe``
writes), a COCO JSON whose ``info`` has ``hpe:system`` (``hpe relabel-agora``,
``hpe relabel-panoptic``), a WHENet ``annotation.txt`` (``whenet``), and the
dataset readers whose format fixes it (300W-LP/AFLW2000 ``.mat``: ``300w_lp``;
BIWI: ``biwi``; DAD-3DHeads: ``dad3dheads``). An explicit option (``--system``,
``--from``, ``--gt-system``, ...) that disagrees with the file's own system is a
usage error naming both, unless ``--reinterpret-as SYSTEM`` says the metadata is
wrong. A file that names no system is read in the option's system, else in the
command's default. Where a command's option names the system it *writes* or
*reports* in (draw's captions, augment's output, evaluate's report) and the
file is a dataset format, the labels are read in the dataset's system and
converted exactly (through the rotation matrix) into the option's.

:func:`resolve_system` returns the system and where it came from (``"file
metadata"``, ``"option"`` or ``"default"``); every resolution made during a
command run is kept (:func:`resolutions`) so the command's summary can say it.
"""

from __future__ import annotations

import contextvars
import json
from dataclasses import dataclass

from ..errors import HpeError, UsageError
from ..rotation.systems import SystemError_, get_system, system_from_dict

FILE, OPTION, DEFAULT = "file metadata", "option", "default"

#: ``--reinterpret-as`` of the running command (set by the CLI, or by an API call's ``reinterpret_as=``)
_REINTERPRET: contextvars.ContextVar = contextvars.ContextVar("hpe_reinterpret_as", default=None)
#: resolutions made during the running command: list of :class:`Resolved` (None outside a run)
_MADE: contextvars.ContextVar = contextvars.ContextVar("hpe_system_resolutions", default=None)


@dataclass(frozen=True)
class Resolved:
    """The system labels are read in, where it came from, and the system to write/report in."""

    system: object  # RotationSystem
    origin: str  # "file metadata" | "option" | "default"
    path: str
    output: object = None  # RotationSystem the command writes/reports in (None: same as ``system``)
    note: str = ""

    def __iter__(self):  # ``system, origin = resolve_system(...)``
        return iter((self.system, self.origin))

    @property
    def origin_text(self) -> str:
        """``"file metadata"``, or with its note: ``"file metadata; --from agrees"``."""
        return f"{self.origin}{'; ' + self.note if self.note else ''}"

    def describe(self) -> str:
        """``"scipy_zyx (file metadata)"``, for summaries."""
        out = f"{self.system.name} ({self.origin_text})"
        if self.output is not None and self.output.name != self.system.name:
            out += f", converted to {self.output.name}"
        return out


def set_reinterpret(system):
    """Hold ``--reinterpret-as`` for the running command; returns a token for :func:`reset_reinterpret`."""
    return _REINTERPRET.set(system)


def reset_reinterpret(token) -> None:
    _REINTERPRET.reset(token)


def start_run():
    """Start collecting resolutions (the command group calls it once per run); returns a reset token."""
    return _MADE.set([])


def end_run(token) -> None:
    _MADE.reset(token)


def resolutions() -> list:
    """The :class:`Resolved` of every table the running command read (empty outside a run)."""
    return list(_MADE.get() or [])


def summary_lines() -> list:
    """One summary line per distinct input: ``labels of FILE: system S (origin)``."""
    seen, out = set(), []
    for r in resolutions():
        line = f"labels of {r.path}: system {r.describe()}"
        if line not in seen:
            seen.add(line)
            out.append(line)
    return out


# ------------------------------------------------------------------------------------------------ the file's own
def system_from_metadata(metadata, path="input"):
    """The RotationSystem a schema's metadata names (``hpe:system_definition``, else ``hpe:system``), or None."""

    meta = {
        (k.decode() if isinstance(k, bytes) else k): (v.decode("utf-8", "replace") if isinstance(v, bytes) else v)
        for k, v in (metadata or {}).items()
    }
    if "hpe:system_definition" in meta:
        try:
            d = json.loads(meta["hpe:system_definition"])
        except ValueError:
            d = None
        if isinstance(d, dict):
            # RotationSystem.to_dict() also writes derived fields that the TOML layout does not take
            if d.pop("angle_frame", "system") == "canonical":
                d.pop("turns", None)
                d.pop("sequence", None)
            for key in [k for k, v in d.items() if v is None]:
                del d[key]
            try:
                return system_from_dict(d, f"{path}: hpe:system_definition")
            except (SystemError_, ValueError, TypeError, KeyError):  # not rebuildable here: use the name
                d = None
    if meta.get("hpe:system"):
        return _named(meta["hpe:system"], path, "hpe:system metadata")
    return None


def _named(name, path, what):

    try:
        return get_system(name)
    except SystemError_:
        raise HpeError(
            f"{path}: {what} names system {name!r}, which this hpe does not know "
            "(pass --reinterpret-as SYSTEM to read the labels in another one)"
        ) from None


def file_system(src):
    """The system ``src`` (a :class:`~hpe_cli.io.readers.TableSource`) names itself, or None."""
    found = system_from_metadata(getattr(src.schema, "metadata", None), src.path)
    if found is not None:
        return found
    if getattr(src, "system", None):
        what = "format" if getattr(src, "dataset", False) else "metadata"
        if getattr(src, "dataset", False):
            try:
                return get_system(src.system)
            except SystemError_:  # a dataset system not built in (yet)
                return None
        return _named(src.system, src.path, what)
    return None


def _same(a, b) -> bool:
    return a is b or (a is not None and b is not None and a.name == b.name)


def resolve_system(
    src,
    option=None,
    *,
    default="300w_lp",
    option_name: str = "--system",
    option_is_output: bool = False,
    reinterpret=None,
) -> Resolved:
    """The system to read ``src``'s labels in, and where it came from.

    Parameters
    ----------
    src : TableSource
        The opened table (:func:`hpe_cli.io.readers.open_table`).
    option : str, path or RotationSystem, optional
        The user's explicit choice (None when not given).
    default : str or None
        The command's default for files that name no system; None makes a
        missing option a usage error.
    option_name : str
        The option's name, for messages (``--from``, ``--gt-system``...).
    option_is_output : bool
        The option names the system the command writes or reports in (draw,
        augment, evaluate): a dataset format's labels are then converted to it
        instead of the disagreement being an error.
    reinterpret : str, path or RotationSystem, optional
        ``--reinterpret-as``: read the labels in this system whatever the file
        says (default: the running command's ``--reinterpret-as``).

    Returns
    -------
    Resolved
        Unpacks as ``(system, origin)``; ``origin`` is ``"file metadata"``,
        ``"option"`` or ``"default"``.

    Raises
    ------
    UsageError
        The option disagrees with the file's own system (exit 2), or neither
        the file nor an option names a system and there is no default.
    """

    path = str(src.path)
    opt = get_system(option) if option is not None else None
    rein = reinterpret if reinterpret is not None else _REINTERPRET.get()
    rein = get_system(rein) if rein is not None else None
    own = file_system(src)
    dataset = bool(getattr(src, "dataset", False))
    out = None
    if own is None:
        if opt is not None:
            res = Resolved(opt, OPTION, path)
        elif rein is not None:
            res = Resolved(rein, OPTION, path, note="--reinterpret-as")
        elif default is not None:
            res = Resolved(get_system(default), DEFAULT, path)
        else:
            raise UsageError(f"{path}: the file names no rotation system: expected {option_name} SYSTEM")
    elif dataset and rein is not None and not _same(rein, own):
        raise UsageError(
            f"{path}: --reinterpret-as {rein.name} does not apply: the file's format fixes its system ({own.name})"
        )
    elif opt is None and rein is None:
        res = Resolved(own, FILE, path)
    elif opt is None or _same(opt, own):
        if rein is not None and not _same(rein, own):
            res = Resolved(rein, OPTION, path, note=f"--reinterpret-as; the file says {own.name}")
        else:  # the user's option names the file's own system: say that they agree
            res = Resolved(own, FILE, path, note=f"{option_name} agrees" if opt is not None else "")
    elif dataset and option_is_output:
        res = Resolved(own, FILE, path)
        out = opt
    elif rein is not None and _same(rein, opt):
        res = Resolved(opt, OPTION, path, note=f"--reinterpret-as; the file says {own.name}")
    else:
        where = "format" if dataset else "metadata"
        hint = "" if dataset else f", or pass --reinterpret-as {opt.name} if the file's metadata is wrong"
        raise UsageError(
            f"{path}: {option_name} {opt.name} disagrees with the file's own system {own.name} "
            f"(its {where}): drop {option_name}{hint}"
        )
    if out is not None or (option_is_output and opt is not None):
        res = Resolved(res.system, res.origin, res.path, out or opt, res.note)
    made = _MADE.get()
    if made is not None:
        made.append(res)
    return res


def output_system(res: Resolved):
    """The system a command writes or reports in after :func:`resolve_system` (``res.output`` or ``res.system``)."""
    return res.output if res.output is not None else res.system
