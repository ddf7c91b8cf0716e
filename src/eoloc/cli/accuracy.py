"""`eoloc accuracy`: the accuracy budget by Monte Carlo."""

from __future__ import annotations

import click
from rich.table import Table as RichTable

from .common import progress
from .main import console, err_console
from .options import dask_option, out_option

ACCURACY_HELP = """Accuracy budget by Monte Carlo: perturb every input by its error law, locate with the
same chain as real fixes, and report the scatter per target.

\b
eoloc accuracy CONFIG.toml            the config's [accuracy] section (pose, stop rule, budget)
eoloc accuracy --scenario s13         built-in: s13 (Sun et al. 2013, Table 1), q-ellipsoid, q-dem
                                      (Qiao et al., Table 1)
  Prints per target: sigma of lat/lon/h, bias and sigma east/north/up (m), CEP50 (empirical and
  parametric bivariate normal), CE90, LE90, DRMS (a radial RMS, not a CEP); then the sensitivity
  of each source alone (mu = sigma_out / sigma_in, as Sun et al. define it). Writes accuracy.csv,
  sensitivity.csv and scatter_target<k>.png (error cloud, CEP circles, mean, 95 % ellipse) into
  --out. Seeded: the same --seed gives the same figures, also on a cluster (--dask ADDRESS, or
  --dask local:N for N local worker processes).
"""

SCENARIOS = ("s13", "q-ellipsoid", "q-dem")


@click.command(help=ACCURACY_HELP)
@click.argument("config_path", required=False, type=click.Path(dir_okay=False))
@click.option("--scenario", type=click.Choice(SCENARIOS), default=None,
              help="A built-in scenario instead of a config file.")
@click.option("--samples", "-n", type=click.IntRange(min=2), default=None,
              help="Monte Carlo samples (default: the config's, else the source's: 10^6 for s13, 5000 for Qiao).")
@click.option("--seed", type=int, default=None, help="Random seed (default: the config's, else 0).")
@click.option("--sensitivity/--no-sensitivity", default=True, show_default=True,
              help="Also run each source alone.")
@click.option("--sensitivity-samples", type=click.IntRange(min=2), default=100_000, show_default=True,
              help="Samples per source for the sensitivity table.")
@click.option("--plots/--no-plots", default=True, show_default=True, help="Write the error scatter plots (PNG).")
@dask_option
@out_option("accuracy.csv, sensitivity.csv and the plots")
def accuracy(config_path, scenario, samples, seed, sensitivity, sensitivity_samples, plots, dask_address,
             out_dir) -> None:
    from ..jobs.accuracy import accuracy_job, mapper, scenario_from

    scn, n, seed = scenario_from(config_path, scenario, samples, seed)
    total = n + (len(scn.budget) * sensitivity_samples if sensitivity else 0)
    with mapper(dask_address) as m, progress() as bar:
        task = bar.add_task("Monte Carlo", total=total)
        job = accuracy_job(scn, n, seed, keep_samples=plots, mapper=m, progress=lambda k: bar.advance(task, k))
    _report(job, scn, n, seed, out_dir, plots)
    if sensitivity:  # after the result is written: an optional step never loses what came before it
        from ..accuracy import sensitivity as run_sensitivity

        with mapper(dask_address) as m, progress() as bar:
            task = bar.add_task("sensitivity", total=len(scn.budget) * sensitivity_samples)
            job.sensitivity = run_sensitivity(scn, sensitivity_samples, seed=seed, mapper=m,
                                              progress=lambda k: bar.advance(task, k))
        _report_sensitivity(job, sensitivity_samples, out_dir)


def _report(job, scn, n: int, seed: int, out_dir, plots: bool) -> None:
    from pathlib import Path

    from ..io.writers import write_layer

    console.print(f"[bold]{scn.name}[/]: {n:,} samples, seed {seed}, stop rule {scn.rule.describe()}; budget: "
                  + ", ".join(f"{s.name} {s.describe()}" for s in scn.budget))
    table = RichTable(title="scatter per target, about the error-free fix")
    table.add_column("quantity")
    for k in range(len(job.rows)):
        table.add_column(f"target {k}", justify="right")
    labels = {"sigma_lat_deg": "σ lat (deg)", "sigma_lon_deg": "σ lon (deg)", "sigma_h_m": "σ h (m)",
              "bias_e_m": "bias east (m)", "bias_n_m": "bias north (m)", "sigma_e_m": "σ east (m)",
              "sigma_n_m": "σ north (m)", "sigma_u_m": "σ up (m)", "cep50_m": "CEP50, empirical (m)",
              "cep50_parametric_m": "CEP50, bivariate normal (m)", "ce90_m": "CE90 (m)", "le90_m": "LE90 (m)",
              "drms_m": "DRMS (m; not a CEP)", "failed": "samples not located"}
    for key, label in labels.items():
        table.add_row(label, *(f"{r[key]:.4g}" if isinstance(r[key], float) else str(r[key]) for r in job.rows))
    console.print(table)
    out = Path(out_dir)
    written = write_layer(out, "accuracy", job.rows, ["csv"])
    if plots:
        from ..accuracy.plots import plot_scatter

        for k in range(min(scn.n_targets, 8)):
            written.append(plot_scatter(job.result, out / f"scatter_target{k}.png", target=k))
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))


def _report_sensitivity(job, sensitivity_samples: int, out_dir) -> None:
    from pathlib import Path

    from ..io.writers import write_layer

    t2 = RichTable(title=f"sensitivity, each source alone (target 0, {sensitivity_samples:,} samples each)")
    for c in ("source", "law", "μ lat (deg/unit)", "μ lon (deg/unit)", "μ h (m/unit)", "σ horizontal (m)"):
        t2.add_column(c, justify="right")
    for r in job.sensitivity:
        t2.add_row(r.source, r.law, f"{r.mu_lat:.4g}", f"{r.mu_lon:.4g}", f"{r.mu_h:.4g}",
                   f"{r.sigma_horizontal_m:.3g}")
    console.print(t2)
    written = write_layer(Path(out_dir), "sensitivity", [vars(r) for r in job.sensitivity], ["csv"])
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
