"""`python -m eoloc ...`: the same as the `eoloc` command."""

from .cli import main

main(prog_name="eoloc")
