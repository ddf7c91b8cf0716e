"""The `eoloc` command line, in rasterio's `rio` shape: the group (:mod:`.main`), the options
declared once (:mod:`.options`), one module per command. Commands render and write what the jobs
(:mod:`eoloc.jobs`) return. Adding a command: a new module defining a click command, and one line
in COMMANDS below."""

from __future__ import annotations

from importlib import import_module

from .main import main

COMMANDS = (  # (module, command object name): registered in this order
    ("locate", "locate"),
    ("footprint", "footprint"),
    ("accuracy", "accuracy"),
    ("sweep", "sweep"),
    ("track", "track"),
    ("triangulate", "triangulate"),
    ("calibrate", "calibrate"),
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

for _module, _name in COMMANDS:
    main.add_command(getattr(import_module(f".{_module}", __name__), _name))

__all__ = ["main"]
