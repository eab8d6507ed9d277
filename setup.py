"""The compiled pieces, both optional: without them ``hpe`` gives the same results, more slowly.

- ``_hpe_jpeg``, a JPEG rectangle decoder over the system's libjpeg-turbo. Without a C compiler or libjpeg-turbo's
  headers (Debian/Ubuntu ``libjpeg-dev``, Fedora ``libjpeg-turbo-devel``, conda ``libjpeg-turbo``) the build skips it
  and ``hpe_cli.io.jpeg`` decodes whole frames (the same pixels, slower on large frames).
- ``_hpe_kernels``, column kernels in plain C (no library; ``csrc/kernels/``, one file per concept): key and row
  hashes, the audit's angle screen, the rotation conversions and evaluate's error formulas. Without a C compiler
  their numpy twins run (``hpe_cli.native``; the same bits).

Either way the build says so in one line per module starting ``hpe:`` (pip shows it with ``pip install -v .``);
``hpe --version`` tells afterwards. Everything else is in ``pyproject.toml``.
"""

import os
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

#: what each optional module does, and what its absence costs (the build's one-line messages)
WHAT = {
    "_hpe_jpeg": (
        "the region JPEG decoder",
        "whole frames will be decoded. For it, install a C compiler and libjpeg-turbo's headers (Debian/Ubuntu "
        "libjpeg-dev, Fedora libjpeg-turbo-devel) and reinstall",
    ),
    "_hpe_kernels": (
        "the compiled column kernels",
        "their numpy twins will run (the same results, slower). For them, install a C compiler and reinstall",
    ),
}


class BuildExt(build_ext):
    """``build_ext`` that reports, in one line per module, whether an optional module was built and why not."""

    def build_extension(self, ext):
        what, without = WHAT[ext.name]
        try:
            super().build_extension(ext)
        except Exception as exc:  # optional=True swallows errors in setuptools; say what happened
            why = f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"
            print(f"hpe: {what} {ext.name} was NOT built ({why}); {without}", file=sys.stderr)
            return
        built = self.get_ext_fullpath(ext.name)
        if os.path.exists(built):
            print(f"hpe: built {what} {ext.name} ({built})", file=sys.stderr)
        else:
            print(f"hpe: {what} {ext.name} was NOT built (no C compiler or headers); {without}", file=sys.stderr)


setup(
    ext_modules=[
        Extension("_hpe_jpeg", ["csrc/_hpe_jpeg.c"], libraries=["jpeg"], optional=True),
        # IEEE arithmetic as numpy does it: no fused multiply-adds (the kernels' twins are numpy passes)
        Extension(
            "_hpe_kernels",
            sorted(str(p) for p in Path("csrc/kernels").glob("*.c")),
            depends=["csrc/kernels/kernels.h"],
            extra_compile_args=["-O3", "-ffp-contract=off"],
            optional=True,
        ),
    ],
    cmdclass={"build_ext": BuildExt},
)
