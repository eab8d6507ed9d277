"""The built-in systems: importing this module registers ``configs/systems/*.toml`` in
:data:`hpe_cli.rotation.systems.SYSTEMS` (a new built-in system is one new TOML file there)."""

from __future__ import annotations

from .systems import read_builtin_systems

read_builtin_systems()
