"""The one compiled part of eoloc: the CSV writer's row renderer (src/eoloc/io/csvrows.c; why it
is hand-written: the README, "Why each dependency"). Everything else is in pyproject.toml.

optional=True: an install without a C compiler still succeeds; the writer then renders through
orjson and pyarrow, the same bytes (tests/test_csvrows.py compares the two).
-ffp-contract=off: x * 10^d and its rounding stay the separate IEEE operations numpy does.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("eoloc.io.csvrows", ["src/eoloc/io/csvrows.c"], optional=True,
                             extra_compile_args=["-O2", "-ffp-contract=off"])])
