"""The one compiled piece: ``_hpe_jpeg``, a JPEG rectangle decoder over the system's libjpeg-turbo.

It is optional: without a C compiler or libjpeg-turbo's headers (Debian/Ubuntu ``libjpeg-dev``, Fedora
``libjpeg-turbo-devel``, conda ``libjpeg-turbo``) the build skips it and ``hpe_cli.io.jpeg`` decodes whole frames
(the same pixels, slower on large frames). Everything else is in ``pyproject.toml``.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("_hpe_jpeg", ["csrc/_hpe_jpeg.c"], libraries=["jpeg"], optional=True)])
