"""Packages whose names are imported on first use (PEP 562), so that importing one (the command
line does, at start-up) does not load every module under it."""

from __future__ import annotations

import sys
from collections.abc import Callable
from importlib import import_module


def lazy_attributes(package: str, where: dict[str, str]) -> Callable[[str], object]:
    """The module ``__getattr__`` of ``package``: a name of ``where`` (name -> submodule) is
    imported from its submodule on first use and kept; a submodule's own name imports it, as an
    eagerly imported package would have it."""

    def attribute(name: str):
        if name in where:
            value = getattr(import_module(f".{where[name]}", package), name)
            setattr(sys.modules[package], name, value)
            return value
        try:
            return import_module(f".{name}", package)
        except ModuleNotFoundError as exc:
            if exc.name != f"{package}.{name}":
                raise
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return attribute
