"""The `eoloc` command line, in rasterio's `rio` shape: the group (:mod:`.main`), the options
declared once (:mod:`.options`), one module per command. Commands render and write what the jobs
(:mod:`eoloc.jobs`) return. Adding a command: a new module defining a click command named as
the module, and one line in COMMANDS below; a command's module is imported only when it runs or
is listed."""

from __future__ import annotations

import sys

from .main import main

COMMANDS = (  # (module, command object name): registered in this order
    ("locate", "locate"),
    ("photo", "photo"),
    ("mux", "mux"),
    ("footprint", "footprint"),
    ("accuracy", "accuracy"),
    ("sweep", "sweep"),
    ("track", "track"),
    ("triangulate", "triangulate"),
    ("calibrate", "calibrate"),
    ("refine", "refine"),
    ("join", "join"),
    ("klv", "klv"),
    ("batch", "batch"),
    ("live", "live"),
    ("map", "map_command"),
    ("compensate", "compensate"),
    ("evaluate", "evaluate"),
    ("report", "report"),
    ("rectify", "rectify"),
    ("video", "video"),
    ("serve", "serve"),
    ("demo", "demo"),
)

for _module, _name in COMMANDS:  # each imported when it runs (or `eoloc --help` lists it)
    main.add_lazy_command(_module, f"{__name__}.{_module}", _name)


def run() -> None:
    """The ``eoloc`` command (console script and ``python -m eoloc``).

    pyarrow imports pandas, where it happens to be installed, at its first conversion of a numpy
    array (0.14 s). eoloc does not use pandas (it is not one of its dependencies), so the command
    runs as it does where pandas is absent: an import of pandas in this process finds nothing.

    pydantic, at the first configuration model it builds, reads the entry points of every
    installed distribution to find its plugins (observability hooks, which the command does not
    use): 5-8 ms here with 119 distributions, more in a large environment. The command turns that
    off unless ``PYDANTIC_DISABLE_PLUGINS`` is set already."""
    import os

    if "pandas" not in sys.modules:
        sys.meta_path.insert(0, _WithoutPandas())
    os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")
    import gc

    # what is loaded so far lives as long as the process: moved out of the collector's way, the
    # full collections of the command's own imports and of the shutdown do not walk it again
    # (~50 ms off `eoloc locate` of 10^6 detections, measured in 10 alternated pairs)
    gc.freeze()
    main(prog_name="eoloc")


class _WithoutPandas:  # a meta path finder (importlib.abc would cost 30 ms of imports)
    def find_spec(self, name, path=None, target=None):
        if name == "pandas" or name.startswith("pandas."):
            raise ModuleNotFoundError(f"No module named {name!r} (the eoloc command does not use pandas)", name=name)
        return None


__all__ = ["main", "run"]
