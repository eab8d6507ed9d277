"""``hpe --version``: the version, and which optional parts this installation has (without importing them)."""

from __future__ import annotations

import click


def _dist_version(name: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return None


def _found(module: str) -> bool:
    import importlib.util

    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def optional_parts() -> list[tuple[str, str]]:
    """``(part, state)`` of each optional part: the region JPEG decoder, the whole-frame decoder, the extras.

    Found from package metadata and module specs (torch and dask are not imported, so this stays fast); the
    region decoder is imported (a small C module) so that a build that cannot load says so.
    """
    parts = []
    try:
        import _hpe_jpeg

        parts.append(
            ("region JPEG decoder", f"built ({_hpe_jpeg.__file__}): JPEG crops decode only their rows and columns")
        )
    except ImportError as exc:
        why = "not built" if isinstance(exc, ModuleNotFoundError) else f"built but cannot load ({exc})"
        parts.append(
            (
                "region JPEG decoder",
                f"{why}: whole frames are decoded (reinstall with a C compiler and libjpeg-turbo's headers, "
                "e.g. Debian/Ubuntu libjpeg-dev)",
            )
        )
    try:
        import _hpe_kernels

        parts.append(("column kernels", f"built ({_hpe_kernels.__file__}): key and row hashes in C"))
    except ImportError as exc:
        why = "not built" if isinstance(exc, ModuleNotFoundError) else f"built but cannot load ({exc})"
        parts.append(
            ("column kernels", f"{why}: their numpy twins run, the same results, slower (reinstall with a C compiler)")
        )
    sj = _dist_version("simplejpeg") if _found("simplejpeg") else None
    parts.append(
        (
            "whole-frame JPEG decoder",
            f"simplejpeg {sj} (where its pixels equal OpenCV's), else OpenCV"
            if sj
            else "OpenCV (simplejpeg not installed; it comes with the torch extra)",
        )
    )
    torch, tv = (_dist_version(n) if _found(n) else None for n in ("torch", "torchvision"))
    parts.append(
        (
            "torch extra",
            f"torch {torch}, torchvision {tv}: hpe_cli.torch is available"
            if torch and tv
            else 'not installed (pip install ".[torch]"): hpe_cli.torch is unavailable',
        )
    )
    dist = _dist_version("distributed") if _found("distributed") else None
    parts.append(
        (
            "dask extra",
            f"distributed {dist}: relabel-panoptic and export --scheduler work"
            if dist
            else 'not installed (pip install ".[dask]"): relabel-panoptic and export --scheduler are unavailable',
        )
    )
    return parts


def version_text() -> str:
    import platform
    from pathlib import Path

    from .. import __version__

    here = Path(__file__).resolve().parents[1]
    lines = [f"hpe {__version__} (Python {platform.python_version()}, {here})"]
    width = max(len(p) for p, _ in optional_parts())
    lines += [f"  {part + ':':<{width + 1}} {state}" for part, state in optional_parts()]
    return "\n".join(lines)


def print_version(ctx, param, value) -> None:
    """Click callback of ``--version``."""
    if not value or ctx.resilient_parsing:
        return
    click.echo(version_text())
    ctx.exit()


def version_option(f):
    """``--version``: the version and the optional parts installed."""
    return click.option(
        "--version",
        is_flag=True,
        expose_value=False,
        is_eager=True,
        callback=print_version,
        help="Show the version and which optional parts are installed (region JPEG decoder, torch and dask "
        "extras), then exit.",
    )(f)
