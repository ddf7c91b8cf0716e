"""`eoloc sweep`: accuracy against the pointing angle and the terrain relief, ellipsoid vs DEM."""

from __future__ import annotations

from pathlib import Path

import click

from .common import progress
from .main import console, err_console, warn
from .options import dask_option, float_list, out_option
from .render import titled_table

SWEEP_HELP = """Accuracy against the pointing angle and the terrain relief, ellipsoid vs DEM (Qiao et al.,
Fig. 10).

\b
eoloc sweep --scenario q-ellipsoid                       Qiao: gimbal roll 10-82 deg, relief sigma 10-100 m
eoloc sweep CONFIG.toml --angle gimbal2 --angles 20:80:10 --terrain-sigmas 10,50
  For every angle and relief sigma, two Monte Carlo runs: on the ellipsoid at the scenario's
  height with the relief as a terrain-height error, and by M4 on a synthetic relief of that
  sigma around the target. Needs a scenario that stops on the ellipsoid (stop = {target_height_m = H}).
  Writes sweep.csv (CEP50 empirical and bivariate normal, CE90, DRMS, sigmas, slant range,
  oblique angle, failed samples) and sweep.png into --out.
"""


@click.command(help=SWEEP_HELP)
@click.argument("config_path", required=False, type=click.Path(dir_okay=False))
@click.option("--scenario", type=click.Choice(["q-ellipsoid"]), default=None, help="A built-in scenario.")
@click.option("--angle", type=click.Choice(["gimbal1", "gimbal2"]), default="gimbal1", show_default=True,
              help="Which gimbal angle to sweep (gimbal1: azimuth / frame roll; gimbal2: elevation / frame pitch).")
@click.option("--angles", default="10:82:8", show_default=True, help="Angles (deg): a,b,c or start:stop:step.")
@click.option("--terrain-sigmas", default="10,25,50,75,100", show_default=True, help="Relief sigmas (m).")
@click.option("--samples", "-n", type=click.IntRange(min=2), default=None,
              help="Monte Carlo samples per point (default 5000, as Qiao et al.).")
@click.option("--seed", type=int, default=None, help="Random seed (default: the config's, else 0).")
@dask_option
@out_option("sweep.csv and sweep.png")
def sweep(config_path, scenario, angle, angles, terrain_sigmas, samples, seed, dask_address, out_dir) -> None:
    from ..accuracy.plots import plot_sweep
    from ..accuracy.sweep import terrain_sweep
    from ..io.writers import write_layer
    from ..jobs.accuracy import mapper, scenario_from

    angle_list, sigma_list = float_list(angles), float_list(terrain_sigmas)
    scn, n, seed = scenario_from(config_path, scenario, samples, seed, default_n=5000)
    methods = ("ellipsoid", "dem")
    with mapper(dask_address) as m, progress() as bar:
        task = bar.add_task("sweep points", total=len(angle_list) * len(sigma_list) * len(methods))
        points = terrain_sweep(scn, angle_list, sigma_list, angle=angle, n=n, seed=seed, methods=methods,
                               mapper=m, progress=lambda k: bar.advance(task, k))
    table = titled_table(f"{scn.name}: CEP50 (m), {n:,} samples per point; ellipsoid / DEM")
    table.add_column(f"{angle} (deg)", justify="right")
    for s in sigma_list:
        table.add_column(f"relief σ {s:g} m", justify="right")
    cep = {(p.method, p.angle_deg, p.terrain_sigma_m): p.cep50_m for p in points}
    for a in angle_list:
        table.add_row(f"{a:g}", *(f"{cep[('ellipsoid', a, s)]:.4g} / {cep[('dem', a, s)]:.4g}" for s in sigma_list))
    console.print(table)
    for p in points:
        if p.note:
            warn(f"{p.method} {angle} {p.angle_deg:g}° σ {p.terrain_sigma_m:g} m: {p.note}")
    out = Path(out_dir)
    (csv_path,) = write_layer(out, "sweep", [vars(p) for p in points], ["csv"])
    png = plot_sweep(points, out / "sweep.png", title=f"{scn.name}: CEP50 against {angle}, {n:,} samples per point")
    err_console.print(f"wrote [bold]{csv_path}[/] and [bold]{png}[/]")
