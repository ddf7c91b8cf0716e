"""`eoloc demo`: the bundled example, run through the jobs (:mod:`.walkthrough`)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import click

from .main import console
from .options import out_option


@click.command(help="Run the bundled example: a short flight over static targets, located by laser range "
                    "and on the ellipsoid, compared with the known truth; a mountain flight on a real DEM; the "
                    "same flight as a MISB KLV stream; learned compensation; an orthorectified frame; and the "
                    "Sun et al. (2013) reference case.")
@out_option("the outputs (CSV, GeoJSON, KML, CoT, the map, GeoTIFF)")
def demo(out_dir) -> None:
    from .walkthrough import run_demo

    run_demo(Path(out_dir), console=console, data=resources.files("eoloc") / "data" / "demo")
