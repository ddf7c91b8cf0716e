"""`python -m eoloc ...`: the same as the `eoloc` command."""

from .cli import run

run()
