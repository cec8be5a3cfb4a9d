"""Only the optional C extension lives here; everything else is in pyproject.toml.

``optional=True``: on a machine without a C compiler (a technician's Windows laptop) the build
skips the extension with a warning and ``sherpa_cli.elmo.codec`` keeps its pure-Python paths.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("sherpa_cli.elmo._codec_c", ["sherpa_cli/elmo/_codec_c.c"], optional=True)])
