"""Rotation systems: the built-ins, lookup by name or file, and the public names of the model.

:mod:`hpe_cli.rotation.system_def` holds :class:`RotationSystem` (what a label means,
as data) and :mod:`hpe_cli.rotation.system_toml` reads and validates system files;
both are re-exported here, the import path of every public name.
"""

from __future__ import annotations

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
    builtin = builtin_systems().get(system.name)
    if builtin is not None and builtin.definition() != system.definition():
        diff = [k for k, v in system.definition().items() if builtin.definition().get(k) != v]
        raise SystemError_(
            f"{path}: name: expected a name that is not a built-in system's, or the built-in's "
            f"definition; got {system.name!r} with a different {', '.join(diff)}"
        )
    return system


def _builtin_dir():
    """``configs/systems``: package data when installed, the repository folder in a source tree."""
    from importlib.resources import files  # lazy: start-up

    source_tree = Path(__file__).resolve().parents[2] / "configs" / "systems"
    if source_tree.is_dir():  # hpe_cli imported from a checkout: its own configs, not an installed copy's
        return source_tree
    return files("hpe_cli.configs") / "systems"


#: name -> built-in :class:`RotationSystem`: the ``configs/systems/*.toml`` files (read on first use, in file
#: name order) and systems a plug-in adds with :func:`register_system`
SYSTEMS = Registry("built-in system", loader="hpe_cli.rotation.systems_builtin")


def register_system(system: RotationSystem) -> RotationSystem:
    """Add ``system`` to the built-in systems (``--system NAME`` then finds it); returns it."""
    SYSTEMS.register(system.name, system)
    return system


def read_builtin_systems() -> None:
    """Register every ``configs/systems/*.toml`` (the loader of :data:`SYSTEMS`)."""
    import tomllib  # lazy: start-up

    for entry in sorted(_builtin_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            register_system(system_from_dict(tomllib.loads(entry.read_text(encoding="utf-8")), entry.name))


def builtin_systems() -> dict:
    """All built-in systems, by name."""
    return dict(SYSTEMS)


def system_names() -> list:
    return list(builtin_systems())


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
    systems = builtin_systems()
    if spec in systems:
        return systems[spec]
    if spec.endswith(".toml") or Path(spec).is_file():
        return load_system(spec)
    raise SystemError_(f"expected a system name ({', '.join(systems)}) or a .toml file, got {spec!r}")
