"""Rotation systems: the built-ins, lookup by name or file, and the public names of the model.

:mod:`hpe_cli.rotation.system_def` holds :class:`RotationSystem` (what a label means,
as data) and :mod:`hpe_cli.rotation.system_toml` reads and validates system files;
both are re-exported here, the import path of every public name.
"""

from __future__ import annotations

import threading
from functools import cache
from pathlib import Path

from ..registry import Registry
from .system_def import (  # noqa: F401
    CANONICAL_TURNS,
    GIMBAL_TOL,
    MATRIX_LAYOUTS,
    ROLES,
    SELECTIONS,
    STORAGE_KINDS,
    RotationSystem,
    SystemError_,
    Turn,
    default_value_names,
)
from .system_toml import (  # noqa: F401
    EXAMPLE_TOL,
    LIMITS,
    check_example,
    example_matrix,
    read_system_file,
    system_from_dict,
)


def load_system(path) -> RotationSystem:
    """Read a system definition from a TOML file (bounded and validated: :mod:`~hpe_cli.rotation.system_toml`).

    A file that uses a built-in system's name must define exactly that system.
    """
    path = Path(path)
    system = read_system_file(path)
    builtin = SYSTEMS.get(system.name, None)
    if builtin is not None and builtin.definition() != system.definition():
        diff = [k for k, v in system.definition().items() if builtin.definition().get(k) != v]
        raise SystemError_(
            f"{path}: name: expected a name that is not a built-in system's, or the built-in's "
            f"definition; got {system.name!r} with a different {', '.join(diff)}"
        )
    return system


def _builtin_dir():
    """``configs/systems``: package data when installed, the repository folder in a source tree."""
    source_tree = Path(__file__).resolve().parents[2] / "configs" / "systems"
    if source_tree.is_dir():  # hpe_cli imported from a checkout: its own configs, not an installed copy's
        return source_tree
    from importlib.resources import files  # lazy: start-up (5 ms), and a source tree does not need it

    return files("hpe_cli.configs") / "systems"


class _Unread:
    """A built-in system file registered by its name and not read yet (:class:`SystemTable`)."""

    __slots__ = ("entry",)

    def __init__(self, entry):
        self.entry = entry


class SystemTable(Registry):
    """:class:`~hpe_cli.registry.Registry` of the built-in systems whose files are read on first use, one by one.

    The loader registers each ``configs/systems/NAME.toml`` under ``NAME`` without reading it; looking a name up
    reads, validates and checks the examples of that file only (0.7 ms, against 13 ms for all 16), and anything
    that lists the systems themselves (``dict``, ``items``, ``values``) reads them all. Names, their order and every
    message are those of a table filled at once.
    """

    _lock = threading.Lock()

    def _read(self, name, entry):
        if not isinstance(entry, _Unread):
            return entry
        with self._lock:  # one reading, one object, whatever the threads
            entry = self._entries.get(name, entry)
            if isinstance(entry, _Unread):
                entry = self._entries[name] = read_builtin_file(entry.entry)
        return entry

    def __getitem__(self, name):
        return self._read(name, super().__getitem__(name))

    def get(self, name, *default):
        return self._read(name, super().get(name, *default))

    def register_file(self, entry) -> None:
        """Register the system file ``entry`` (a path, ``NAME.toml``) under ``NAME``, to be read on first use."""
        self.register(entry.name.removesuffix(".toml"), _Unread(entry))


#: name -> built-in :class:`RotationSystem`: the ``configs/systems/*.toml`` files (registered on first use, in
#: file name order, each read when first looked up) and systems a plug-in adds with :func:`register_system`
SYSTEMS = SystemTable("built-in system", loader="hpe_cli.rotation.systems_builtin")


def register_system(system: RotationSystem) -> RotationSystem:
    """Add ``system`` to the built-in systems (``--system NAME`` then finds it); returns it."""
    SYSTEMS.register(system.name, system)
    return system


def read_builtin_file(entry) -> RotationSystem:
    """The system of the built-in file ``entry`` (``configs/systems/NAME.toml``), which must be called ``NAME``."""
    import tomllib  # lazy: start-up

    system = system_from_dict(tomllib.loads(entry.read_text(encoding="utf-8")), entry.name)
    stem = entry.name.removesuffix(".toml")
    if system.name != stem:
        raise SystemError_(
            f"{entry.name}: name: expected {stem!r} (a built-in system's file is named after it), got {system.name!r}"
        )
    return system


def read_builtin_systems() -> None:
    """Register every ``configs/systems/*.toml`` by its name, unread (the loader of :data:`SYSTEMS`)."""
    for entry in sorted(_builtin_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            SYSTEMS.register_file(entry)


def builtin_systems() -> dict:
    """All built-in systems, by name (every file read)."""
    return dict(SYSTEMS)


def system_names() -> list:
    """The built-in systems' names (no file read)."""
    return list(SYSTEMS)


@cache
def canonical_system() -> RotationSystem:
    """The 300W-LP system: hpe's canonical frame (``to_canonical`` is the identity) and the default system of
    labels that name none (300W-LP/AFLW2000 ``Pose_Para``, tables without ``hpe:system``)."""
    return get_system("300w_lp")


def get_system(spec) -> RotationSystem:
    """A built-in system by name, a TOML file path, or a ``RotationSystem`` as is."""
    if isinstance(spec, RotationSystem):
        return spec
    spec = str(spec)
    if spec in SYSTEMS:
        return SYSTEMS[spec]
    if spec.endswith(".toml") or Path(spec).is_file():
        return load_system(spec)
    raise SystemError_(f"expected a system name ({', '.join(SYSTEMS)}) or a .toml file, got {spec!r}")
