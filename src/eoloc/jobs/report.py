"""The `eoloc report` job: from GCP observations (reported pose, pixel, surveyed point) to a
flight-test accuracy report — locate every observation (with its covariance when the config has
an error budget), evaluate against the surveyed points, calibrate the installation (before/after,
and after with each flight held out of its own calibration), optionally cross-validate the learned
compensation, and lay it all out as one self-contained HTML page plus CSV."""

from __future__ import annotations

import dataclasses
import hashlib
import platform
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import InputError
from ..io.html_report import Page
from ..io.records import Records
from ..io.table import Issue
from ..rules import StopRule
from .evaluate import Evaluation, evaluate_errors, evaluation_notes, evaluation_tables, figures, summary_rows

MAX_HELD_OUT_FLIGHTS = 40  # leave-one-flight-out calibration beyond this many flights: by a note instead


@dataclass
class Stage:
    """One way of locating the observations: its name, the errors of every observation (N, 3; NaN
    where not located) and their evaluation."""

    name: str
    enu_m: np.ndarray
    evaluation: Evaluation


@dataclass
class ReportJob:
    stages: list[Stage]
    calibration: object | None
    compensation_rows: list | None
    page: Page
    points: Records
    issues: list[Issue] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _locate(sensor, pose, uv, rule, budget):
    """(fixes, covariance columns or None)."""
    if budget is None:
        return rule.locate(sensor, pose, uv), None
    from ..accuracy.covariance import covariance_columns, locate_with_covariance

    fixes, cov = locate_with_covariance(sensor, pose, budget, uv, rule)
    return fixes, covariance_columns(cov, fixes.ok)


def report_job(cfg, config_path, observations, *, rule: StopRule | None = None,
               estimate: tuple[str, ...] = ("mount",), compensation: bool = False, n_boot: int = 2000,
               level: float = 0.95, seed: int = 0, cooks_threshold: float | None = None, command: str = "",
               progress=None) -> ReportJob:
    from ..accuracy import compensation as C
    from ..io.telemetry import read_observations
    from ..sequence.calibration import GROUPS, calibrate
    from .setup import optional_budget

    step = progress or (lambda text: None)
    bad = [g for g in estimate if g not in GROUPS or g == "time"]
    if bad:
        raise InputError(f"--estimate: {bad[0]!r} cannot be estimated from observations; choose from mount, "
                         "boresight, heading")
    t = read_observations(observations)
    issues = list(t.issues)
    if len(t) == 0:
        raise InputError(f"{observations}: no usable observation", issues)
    sensor = cfg.sensor()
    budget = optional_budget(cfg)
    c = t.columns
    pose, uv = C.observation_pose(c)
    stop_rule = C.observation_rule(c, rule)
    truth = C.observation_truth(c)
    flights = np.asarray(c["flight"], dtype=object).astype(str)
    kw = {"n_boot": n_boot, "level": level, "seed": seed, "cooks_threshold": cooks_threshold}

    step("locating")
    fixes, cov = _locate(sensor, pose, uv, stop_rule, budget)
    feats = C.error_features(sensor, pose, fixes, uv)
    cam = sensor.camera
    factor_values = {"range_m": ("slant range (m)", np.asarray(fixes.range_m, dtype=np.float64)),
                     "oblique_deg": ("oblique angle (deg from the vertical)", np.asarray(feats.oblique_deg)),
                     "azimuth_deg": ("look azimuth (deg from north)", np.asarray(feats.azimuth_deg)),
                     "aircraft_roll_deg": ("aircraft roll (deg)", np.asarray(c["roll_deg"], dtype=np.float64)),
                     "pixel_radius_px": ("distance from the image centre (px)",
                                         np.hypot(c["u_px"] - cam.cx, c["v_px"] - cam.cy))}
    ids = {"line": np.asarray(t.line), "flight": flights,
           "gcp_id": np.asarray(c.get("gcp_id", np.full(len(t), "", dtype=object)), dtype=object)}

    own_height = rule is None  # the vertical error is zero by construction

    def judge(name: str, enu: np.ndarray, covariance=None) -> Stage:
        """A stage from the errors of every observation (NaN where not located)."""
        if own_height:
            enu[:, 2] = np.nan
        ok = np.all(np.isfinite(enu[:, :2]), -1)
        if not ok.any():
            raise InputError(f"{observations}: no observation could be located ({name})", issues)
        ev = evaluate_errors(enu[ok], groups=flights[ok], group_column="flight",
                             factors={k: (lab, v[ok]) for k, (lab, v) in factor_values.items()},
                             covariance=None if covariance is None else {k: v[ok] for k, v in covariance.items()},
                             columns={k: v[ok] for k, v in ids.items()}, **kw)
        ev.n_fixes = len(t)
        return Stage(name, enu, ev)

    def stage(name: str, fx, covariance) -> Stage:
        return judge(name, np.where(np.asarray(fx.ok)[:, None], C.error_enu(fx, truth), np.nan), covariance)

    stages = [stage("as located", fixes, cov)]
    notes = []
    if own_height:
        notes.append("located on each point's own surveyed height: the vertical errors are zero by construction "
                     "and left out (locate with --dem or --target-height for vertical statistics)")
    if not fixes.ok.all():
        notes.append(f"{int((~fixes.ok).sum())} observations could not be located ({fixes.status_counts()}); they "
                     "are left out")
    cal = None
    if estimate:
        step("calibrating")
        pixels = np.c_[uv[0], uv[1]]
        cal = calibrate(sensor, pixels, truth, pose=pose, estimate=tuple(estimate))
        notes += cal.warnings[:5]
        pose_after = dataclasses.replace(pose, yaw_deg=np.asarray(pose.yaw_deg) - cal.heading_bias_deg)
        fx, cv = _locate(cal.sensor, pose_after, uv, stop_rule, budget)
        stages.append(stage("calibrated (in sample)", fx, cv))
        names = sorted(set(flights.tolist()))
        if 2 <= len(names) <= MAX_HELD_OUT_FLIGHTS:
            step("calibrating with each flight held out")
            held = np.full((len(t), 3), np.nan)
            for f in names:
                m = flights == f
                cal_f = calibrate(sensor, pixels[~m], truth[~m], pose=pose.take(~m), estimate=tuple(estimate))
                p_f = pose.take(m)
                p_f = dataclasses.replace(p_f, yaw_deg=p_f.yaw_deg - cal_f.heading_bias_deg)
                rule_f = C.observation_rule({k: np.asarray(v)[m] for k, v in c.items()}, rule)
                fx_f = rule_f.locate(cal_f.sensor, p_f, (uv[0][m], uv[1][m]))
                held[m] = np.where(np.asarray(fx_f.ok)[:, None], C.error_enu(fx_f, truth[m]), np.nan)
            stages.append(judge("calibrated (flight held out)", held))
        elif len(names) < 2:
            notes.append("one flight only: the calibration is judged on the observations it was fitted to (in "
                         "sample); observations from a second flight would show how well it carries over")
    comp_rows, comp_fig = None, None
    if compensation:
        step("cross-validating the compensation")
        comp_rows, comp_fig = _compensation(C, feats, stages[0].enu_m, flights, fixes.ok, notes)
    step("writing the report")
    points = _points(ids, stages, factor_values)
    page = _page(observations, config_path, t, stages, cal, estimate, comp_rows, comp_fig, rule,
                 budget, issues, notes, command, level)
    return ReportJob(stages, cal, comp_rows, page, points, issues, notes)


def _compensation(C, feats, enu, flights, ok, notes):
    from ..accuracy.plots import compensation_figure

    ok = np.asarray(ok) & np.all(np.isfinite(enu[:, :2]), -1)
    if len(set(flights[ok].tolist())) < 2:
        notes.append("compensation: cross-validation holds whole flights out and needs at least two flights")
        return None, None
    idx = np.flatnonzero(ok)
    cv = C.cross_validate(feats.take(idx), enu[idx], flights[idx], by="flight", feature_sets=("p+bearing",),
                          trees=False)
    rows = cv.table(C.DEFAULT_BANDS)
    fig = compensation_figure(cv.oblique_deg, cv.before_en, {"p+bearing": cv.after_en["p+bearing"]}, rows,
                              title="held-out flights: horizontal error against oblique angle, before and after")
    return rows, fig


def _points(ids, stages: list[Stage], factors) -> Records:
    cols = dict(ids)
    for s in stages:
        key = {"as located": "located", "calibrated (in sample)": "calibrated",
               "calibrated (flight held out)": "held_out"}[s.name]
        cols[f"{key}_e_m"], cols[f"{key}_n_m"], cols[f"{key}_u_m"] = s.enu_m.T
        cols[f"{key}_horizontal_m"] = np.hypot(s.enu_m[:, 0], s.enu_m[:, 1])
    cols.update({k: v for k, (_, v) in factors.items()})
    return Records(cols)


def _sha256(path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def _versions() -> list[list[str]]:
    from importlib.metadata import PackageNotFoundError, version

    rows = [["eoloc", __version__], ["Python", platform.python_version()]]
    for name in ("numpy", "scipy", "pyproj", "matplotlib", "rasterio"):
        try:
            rows.append([name, version(name)])
        except PackageNotFoundError:
            rows.append([name, "not installed"])
    return rows


def _page(observations, config_path, table, stages, cal, estimate, comp_rows, comp_fig, rule,
          budget, issues, notes, command, level) -> Page:
    from ..accuracy.plots import figure_png

    page = Page(f"eoloc accuracy report: {Path(str(observations)).name}")
    first = stages[0].evaluation
    stop = ("the DEM" if rule is not None and rule.terrain is not None else rule.describe() if rule is not None
            else "each point's own surveyed height (isolates the angular errors)")
    page.text(f"{len(table)} observations of surveyed points on {len(set(table.columns['flight'].tolist()))} "
              f"flight(s), located on {stop}; generated {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')} by eoloc "
              f"{__version__}.")
    keys = []
    for s in stages:
        v = s.evaluation.overall.value
        keys.append((f"CEP {s.name}", f"{v['cep50_m']:.2f} m"))
    keys.append(("CE90 as located", f"{first.overall.value['ce90_m']:.2f} m"))
    if np.isfinite(first.overall.value["le90_m"]):
        keys.append(("LE90 as located", f"{first.overall.value['le90_m']:.2f} m"))
    page.key_figures(keys)
    page.items(notes, "note")

    page.heading("Accuracy as located")
    for t in evaluation_tables(first):
        page.table_data(t)
    page.items(evaluation_notes(first), "note")
    captions = {"errors": "east/north errors with the CEP and CE90 circles about the true point; vertical errors",
                "factors": "horizontal error against slant range, oblique angle, look azimuth, aircraft roll and "
                           "the pixel's distance from the image centre, with the median and 90 % per bin and the "
                           "TLE line",
                "coverage": "share of surveyed points inside each fix's own predicted region against its "
                            "probability: an honest uncertainty follows the diagonal"}
    for name, fig in figures(first).items():
        page.figure(figure_png(fig), captions[name], f"located-{name}")
    if budget is None:
        page.text("The config has no [accuracy.budget]: the fixes carry no covariance, so the honesty of the "
                  "predicted uncertainty is not assessed.", "note")

    if cal is not None:
        page.heading("Installation calibration")
        page.text(f"Estimated: {', '.join(estimate)}, by least squares on the pixel residuals of every observation "
                  f"(s0 = {cal.s0:.2f}). 'In sample' locates the same observations again with the estimate; "
                  "'flight held out' locates each flight with an estimate made without it — the figure to expect "
                  "on the next flight.")
        page.table(["parameter", "estimate", "± 1σ"], [[n, f"{v:.4f}", f"{s:.4f}"] for n, v, s in
                                                      zip(cal.names, cal.values, cal.sigma, strict=True)])
        keys = ("cep50_m", "ce90_m", "le90_m", "rmse_h_m", "bias_e_m", "bias_n_m", "bias_u_m")
        rows = []
        for s in stages:
            x = s.evaluation.overall
            rows.append([s.name, str(x.n), *(f"{x.value[k]:.2f} ({x.low[k]:.2f} – {x.high[k]:.2f})" for k in keys)])
        page.table(["", "n", "CEP", "CE90", "LE90", "RMSE h", "bias E", "bias N", "bias U"], rows,
                   f"metres, with {level:.0%} bootstrap intervals")
        for k, s in enumerate(stages[1:], start=1):
            page.figure(figure_png(figures(s.evaluation, title=s.name)["errors"]), f"errors, {s.name}",
                        f"stage{k}-errors")
    if comp_rows is not None:
        page.heading("Learned compensation, cross-validated by flight")
        page.table(["oblique band", "n", "CEP located (m)", "CEP compensated (m)", "change"],
                   [[(f"> {r.lo_deg:.0f}°" if r.summary else f"{r.lo_deg:.0f}–{r.hi_deg:.0f}°"), str(r.n),
                     f"{r.cep_before_m:.2f}", f"{r.cep_after_m['p+bearing']:.2f}",
                     f"{-100 * r.reduction('p+bearing'):+.0f} %"] for r in comp_rows],
                   "each flight's errors predicted by a model trained on the other flights")
        page.figure(figure_png(comp_fig), "horizontal error against oblique angle before and after the "
                                          "compensation, and CEP by oblique band", "compensation")

    page.heading("Inputs and versions")
    paths = [observations, config_path, *(rule.terrain.files if rule is not None and rule.terrain is not None else ())]
    files = [[str(p), f"{Path(p).stat().st_size:,} bytes", _sha256(p)] for p in paths]  # the DEM tiles too
    page.table(["file", "size", "SHA-256"], files, align="lrl")
    if command:
        page.pre(command)
    page.heading("configuration", 3)
    page.pre(Path(config_path).read_text(encoding="utf-8", errors="replace"))
    page.heading("software", 3)
    page.table(["package", "version"], _versions(), align="ll")
    if issues:
        page.heading("input issues (the records kept going)", 3)
        page.items([str(i) for i in issues[:200]] + ([f"... and {len(issues) - 200} more"] if len(issues) > 200
                                                     else []))
    return page


def write_report(job: ReportJob, out_dir) -> list[Path]:
    """report.html, report_points.csv (every observation, each stage's errors) and
    report_summary.csv (each stage's statistics, overall and per flight)."""
    from ..io.writers import write_layer

    out = Path(out_dir)
    written = [job.page.write(out / "report.html")]
    written += write_layer(out, "report_points", job.points, ["csv"])
    rows = [{"stage": s.name, **r} for s in job.stages for r in summary_rows(s.evaluation)]
    written += write_layer(out, "report_summary", rows, ["csv"])
    return written
