"""`eoloc accuracy`: the accuracy budget by Monte Carlo."""

from __future__ import annotations

import click

from .common import load_config, open_dem, progress, stop_rule, working
from .main import console, err_console, report_issues
from .options import (
    CONVENTIONS,
    config_option,
    dask_option,
    formats_option,
    out_option,
    pairing_options,
    stop_rule_options,
)
from .render import titled_table

ACCURACY_HELP = """Accuracy budget by Monte Carlo: perturb every input by its error law, locate with the
same chain as real fixes, and report the scatter per target.

\b
eoloc accuracy CONFIG.toml            the config's [accuracy] section (pose, stop rule, budget)
eoloc accuracy --scenario s13         built-in: s13 (Sun et al. 2013, Table 1), q-ellipsoid, q-dem
                                      (Qiao et al., Table 1)
  --range R, --target-height H or --dem F replace the scenario's stop rule; the config's DEM
  files are relative to it, read with its [accuracy.stop] dem_vertical and dem_crs (or --dem-crs).
  Prints per target: sigma of lat/lon/h, bias and sigma east/north/up (m), CEP50 (empirical and
  parametric bivariate normal), CE90, LE90, DRMS (a radial RMS, not a CEP); then the sensitivity
  of each source alone (mu = sigma_out / sigma_in, as Sun et al. define it). Writes accuracy.csv,
  sensitivity.csv and scatter_target<k>.png (error cloud, CEP circles, mean, 95 % ellipse) into
  --out. Seeded: the same --seed gives the same figures, also on a cluster (--dask ADDRESS, or
  --dask local:N for N local worker processes).

\b
eoloc accuracy TELEMETRY.csv DETECTIONS.csv --config CAMERA.toml (--range [R] | --target-height H | --dem F)
  The flight you flew: every detection located with the config's [accuracy.budget], then per fix
  and per target (its fixes combined as eoloc track --static does) the first-order CEP50, CE90
  and LE90, the CE90 of the biases, Gauss–Markov errors and noise alone (what averaging over
  frames cannot remove, what it partly removes, what it removes), and the same figures by Monte
  Carlo: -n copies of the whole flight with errors drawn as the budget says they behave in time
  (a bias once, noise every frame, Gauss–Markov over the frames' times). Where the two disagree
  the chain is not linear there: use the Monte Carlo figure. Writes accuracy_fixes and
  accuracy_targets (--format) and accuracy_flight.png (CE90 per target, split by kind).
eoloc accuracy FLIGHT.klv|.ts --config CAMERA.toml [--dem F]
  The same for a MISB stream's ST 0903 VMTI targets (MISB sensor, the config's [installation]
  and [accuracy.budget]; on the DEM, else each packet's frame-centre elevation).
"""

SCENARIOS = ("s13", "q-ellipsoid", "q-dem")


@click.command(help=ACCURACY_HELP + CONVENTIONS)
@click.argument("inputs", nargs=-1, type=click.Path(dir_okay=False),
                metavar="[CONFIG.toml | TELEMETRY DETECTIONS | FLIGHT.klv]")
@config_option(required=False, help_text="Flight mode: the camera TOML with its [accuracy.budget].")
@stop_rule_options
@pairing_options
@formats_option()
@click.option("--scenario", type=click.Choice(SCENARIOS), default=None,
              help="A built-in scenario instead of a config file.")
@click.option("--samples", "-n", type=click.IntRange(min=2), default=None,
              help="Monte Carlo samples (default: the config's, else the source's: 10^6 for s13, 5000 for Qiao; "
                   "a flight: 1000 copies of it).")
@click.option("--seed", type=int, default=None, help="Random seed (default: the config's, else 0).")
@click.option("--sensitivity/--no-sensitivity", default=True, show_default=True,
              help="Also run each source alone.")
@click.option("--sensitivity-samples", type=click.IntRange(min=2), default=100_000, show_default=True,
              help="Samples per source for the sensitivity table.")
@click.option("--plots/--no-plots", default=True, show_default=True, help="Write the error scatter plots (PNG).")
@dask_option
@out_option("accuracy.csv, sensitivity.csv and the plots")
def accuracy(inputs, config_path, rule_values, dem_paths, vertical, geoid, dem_crs, time_tolerance,
             interpolate, max_gap, time_offset, formats, scenario, samples, seed, sensitivity, sensitivity_samples,
             plots, dask_address, out_dir) -> None:
    from ..jobs.accuracy import accuracy_job, mapper, scenario_from

    if len(inputs) == 2:
        return _flight(inputs, config_path, stop_rule(rule_values,
                                                      open_dem(dem_paths, vertical, geoid, dem_crs)),
                       dict(time_tolerance_s=time_tolerance, interpolate=interpolate, max_gap_s=max_gap,
                            time_offset_s=time_offset), formats, samples or 1000, seed or 0, plots, out_dir)
    if len(inputs) == 1 and config_path is not None:  # a KLV or MPEG-TS file's VMTI targets
        if any(v is not None for v in rule_values.values()):
            raise click.UsageError("a KLV flight's targets stop on --dem F or on each packet's frame-centre elevation")
        return _flight(inputs, config_path, open_dem(dem_paths, vertical, geoid, dem_crs), None, formats,
                       samples or 1000, seed or 0, plots, out_dir)
    if len(inputs) > 2 or config_path is not None:
        raise click.UsageError("give CONFIG.toml (a scenario), or TELEMETRY DETECTIONS --config CAMERA.toml (a flight)")
    config_path = inputs[0] if inputs else None
    rule = stop_rule(rule_values, open_dem(dem_paths, vertical, geoid, dem_crs), required=False)
    from ..rules import RangeFromRecords

    if isinstance(rule, RangeFromRecords):
        raise click.UsageError("--range needs a value (metres) for a scenario: there are no files to take it from")
    scn, n, seed = scenario_from(config_path, scenario, samples, seed, rule=rule, dem_crs=dem_crs)
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
    table = titled_table("scatter per target, about the error-free fix")
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

    t2 = titled_table(f"sensitivity, each source alone (target 0, {sensitivity_samples:,} samples each)")
    for c in ("source", "law", "μ lat (deg/unit)", "μ lon (deg/unit)", "μ h (m/unit)", "σ horizontal (m)"):
        t2.add_column(c, justify="right")
    for r in job.sensitivity:
        t2.add_row(r.source, r.law, f"{r.mu_lat:.4g}", f"{r.mu_lon:.4g}", f"{r.mu_h:.4g}",
                   f"{r.sigma_horizontal_m:.3g}")
    console.print(t2)
    written = write_layer(Path(out_dir), "sensitivity", [vars(r) for r in job.sensitivity], ["csv"])
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))


def _flight(inputs, config_path, rule, pairing: dict | None, formats, n: int, seed: int, plots: bool, out_dir) -> None:
    from pathlib import Path

    from ..io.writers import write_layer
    from ..jobs.accuracy import flight_job, klv_flight_job

    if config_path is None:
        raise click.UsageError("the accuracy of a flight needs --config CAMERA.toml with its [accuracy.budget]")
    cfg = load_config(config_path)
    with working("locating..."), progress() as bar:
        task = bar.add_task("Monte Carlo of the flight", total=n)
        if pairing is None:  # rule: the DEM or None
            fa, issues = klv_flight_job(cfg, config_path, inputs[0], rule, samples=n, seed=seed,
                                        progress=lambda k: bar.advance(task, k))
        else:
            fa, job = flight_job(cfg, config_path, inputs[0], inputs[1], rule, samples=n, seed=seed,
                                 progress=lambda k: bar.advance(task, k), **pairing)
            issues = job.issues
    report_issues(issues)
    table = titled_table(f"the flight's targets: first order and Monte Carlo ({n:,} copies of the flight)")
    for c in ("target", "fixes", "CE90", "MC", "LE90", "MC", "bias", "G–M", "noise", "1 fix"):
        table.add_column(c, justify="right", overflow="fold")
    f = lambda r, k: f"{r[k]:.2f}" if isinstance(r.get(k), float) else ""  # noqa: E731
    for r in fa.targets:
        if r["status"] != "OK":
            table.add_row(r["target_id"], str(r["fixes"]), r["status"], "", "", "", "", "", "", "")
            continue
        table.add_row(r["target_id"], str(r["fixes"]), f(r, "ce90_m"), f(r, "mc_ce90_m"), f(r, "le90_m"),
                      f(r, "mc_le90_m"), f(r, "ce90_bias_m"), f(r, "ce90_markov_m"), f(r, "ce90_noise_m"),
                      f(r, "single_fix_ce90_m"))
    console.print(table)
    console.print("metres; CE90 / LE90: first order, MC: Monte Carlo; bias, G–M (Gauss–Markov), noise: the CE90 of "
                  "each kind of source alone (they add as variances: a bias never averages down over frames); "
                  "1 fix: the median CE90 of one fix. INCONSISTENT: the target's fixes do not agree with one point.")
    out = Path(out_dir)
    written = write_layer(out, "accuracy_fixes", fa.fixes, formats)
    written += write_layer(out, "accuracy_targets", fa.targets, formats)
    if plots:
        from ..accuracy.plots import plot_flight_accuracy

        written.append(plot_flight_accuracy(fa, out / "accuracy_flight.png"))
    err_console.print("wrote " + ", ".join(f"[bold]{p}[/]" for p in written))
