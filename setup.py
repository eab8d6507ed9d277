"""The one compiled piece: ``_hpe_jpeg``, a JPEG rectangle decoder over the system's libjpeg-turbo.

It is optional: without a C compiler or libjpeg-turbo's headers (Debian/Ubuntu ``libjpeg-dev``, Fedora
``libjpeg-turbo-devel``, conda ``libjpeg-turbo``) the build skips it and ``hpe_cli.io.jpeg`` decodes whole frames
(the same pixels, slower on large frames). Either way the build says so in one line starting ``hpe:`` (pip shows
it with ``pip install -v .``); ``hpe --version`` tells afterwards. Everything else is in ``pyproject.toml``.
"""

import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildExt(build_ext):
    """``build_ext`` that reports, in one line, whether the optional decoder was built and why not."""

    def build_extension(self, ext):
        try:
            super().build_extension(ext)
        except Exception as exc:  # optional=True swallows errors in setuptools; say what happened
            print(
                f"hpe: the region JPEG decoder {ext.name} was NOT built ({type(exc).__name__}: "
                f"{' '.join(str(exc).split())[:200]}); whole frames will be decoded. For it, install a C compiler "
                "and libjpeg-turbo's headers (Debian/Ubuntu libjpeg-dev, Fedora libjpeg-turbo-devel) and reinstall",
                file=sys.stderr,
            )
            return
        built = self.get_ext_fullpath(ext.name)
        import os

        if os.path.exists(built):
            print(f"hpe: built the region JPEG decoder {ext.name} ({built})", file=sys.stderr)
        else:
            print(
                f"hpe: the region JPEG decoder {ext.name} was NOT built (no C compiler or no jpeglib.h); whole "
                "frames will be decoded. For it, install a C compiler and libjpeg-turbo's headers (Debian/Ubuntu "
                "libjpeg-dev, Fedora libjpeg-turbo-devel) and reinstall",
                file=sys.stderr,
            )


setup(
    ext_modules=[Extension("_hpe_jpeg", ["csrc/_hpe_jpeg.c"], libraries=["jpeg"], optional=True)],
    cmdclass={"build_ext": BuildExt},
)
