"""The `eoloc evaluate` job: fixes against surveyed points — match, errors, statistics with their
bootstrap intervals (overall and by group), error against geometry with the linear TLE model in
slant range, and the honesty of the fixes' own uncertainty. No printing here: the CLI renders,
:func:`write_evaluation` writes."""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..accuracy import evaluation as E
from ..errors import InputError
from ..io.points import Points, read_points
from ..io.records import Records
from ..io.table import Issue

#: Factors recognised by column name in the fixes: canonical name -> (label, accepted columns)
FACTORS = {
    "range_m": ("slant range (m)", ("range_m", "slant_range_m", "slant_range", "range")),
    "oblique_deg": ("oblique angle (deg from the vertical)", ("oblique_deg", "oblique_angle_deg", "off_nadir_deg")),
    "azimuth_deg": ("look azimuth (deg from north)", ("azimuth_deg", "look_azimuth_deg")),
    "roll_deg": ("camera roll (deg)", ("sensor_roll_deg", "camera_roll_deg", "gimbal_roll_deg")),
    "pixel_radius_px": ("distance from the image centre (px)", ("pixel_radius_px",)),
}
FIX_IDS = ("target_id", "gcp_id", "id", "name", "callsign", "track_id")
TRUTH_IDS = ("gcp_id", "target_id", "id", "name", "point_id", "callsign")
FEW = 30  # [Z15]: at least 30 samples for a 90 % statement


@dataclass
class Evaluation:
    """Everything `eoloc evaluate` and `eoloc report` show: per-point ``rows``, the summary of all
    points and of each group, the factors and their bins, the TLE fit (all and per group), the
    coverage of the predicted uncertainty, and what could not be used and why."""

    rows: Records
    summaries: dict[str, E.Summary]
    group_column: str | None
    factors: dict[str, tuple[str, np.ndarray]]
    bins: dict[str, list[E.Bin]]
    tle: dict[str, E.LinearFit | None]
    coverage: E.Coverage | None
    enu_m: np.ndarray
    match: str = "paired"
    n_fixes: int = 0
    unmatched: int = 0
    unmatched_example: str = ""
    ambiguous: int = 0
    not_located: Counter = field(default_factory=Counter)
    issues: list[Issue] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    inputs: dict[str, str] = field(default_factory=dict)

    @property
    def overall(self) -> E.Summary:
        return self.summaries["all"]


def _first(points: Points, names) -> str | None:
    return next((n for n in names if points.column(n) is not None), None)


def evaluate_errors(enu_m: np.ndarray, *, groups: np.ndarray | None = None, group_column: str | None = None,
                    factors: dict[str, tuple[str, np.ndarray]] | None = None,
                    covariance: dict[str, np.ndarray] | None = None, columns: dict[str, np.ndarray] | None = None,
                    n_boot: int = 2000, level: float = 0.95, seed: int = 0,
                    cooks_threshold: float | None = None) -> Evaluation:
    """Statistics of paired errors ``enu_m`` (N, 3) (fix minus truth, east/north/up m).
    ``groups`` (N,) labels; ``factors``: name -> (label, (N,) values); ``covariance``: the fixes'
    sigma_e_m, sigma_n_m, rho_en[, sigma_u_m, cep50_m, ce90_m, le90_m] columns; ``columns``: what
    goes first in each per-point row (ids, places)."""
    enu = np.asarray(enu_m, dtype=np.float64).reshape(-1, 3)
    n = enu.shape[0]
    horizontal = np.hypot(enu[:, 0], enu[:, 1])
    factors = {k: v for k, v in (factors or {}).items() if np.isfinite(v[1]).sum() >= 2}
    summaries = {"all": E.summarize(enu, n_boot=n_boot, level=level, seed=seed)}
    tle = {"all": E.tle_fit(factors["range_m"][1], horizontal, threshold=cooks_threshold)
           if "range_m" in factors else None}
    if groups is not None:
        g = np.array([str(x) if str(x) else "(none)" for x in np.asarray(groups, dtype=object)], dtype=object)
        for label in sorted(set(g.tolist())) if len(set(g.tolist())) > 1 else ():
            m = g == label
            summaries[label] = E.summarize(enu[m], n_boot=n_boot, level=level, seed=seed)
            if "range_m" in factors:
                tle[label] = E.tle_fit(factors["range_m"][1][m], horizontal[m], threshold=cooks_threshold)
    bins = {k: E.binned(x, horizontal, enu[:, 2]) for k, (_, x) in factors.items()}
    cov = None
    if covariance is not None and all(k in covariance for k in ("sigma_e_m", "sigma_n_m")):
        c = covariance
        cov = E.coverage(enu, c["sigma_e_m"], c["sigma_n_m"], c.get("rho_en", np.zeros(n)), c.get("sigma_u_m"),
                         cep50_m=c.get("cep50_m"), ce90_m=c.get("ce90_m"), le90_m=c.get("le90_m"))
    cols = dict(columns or {})
    if groups is not None:
        cols[group_column or "group"] = np.asarray(groups, dtype=object)
    cols.update({"err_e_m": enu[:, 0], "err_n_m": enu[:, 1], "err_u_m": enu[:, 2], "horizontal_m": horizontal,
                 "vertical_m": enu[:, 2]})
    for k, (_, x) in factors.items():
        cols[k] = np.asarray(x, dtype=np.float64)
    if tle["all"] is not None:
        cols["cooks_distance"] = tle["all"].cooks
        cols["tle_kept"] = tle["all"].kept
    notes = []
    if summaries["all"].n < FEW:
        notes.append(f"{summaries['all'].n} points: fewer than {FEW}, too few for a 90 % figure to mean much "
                     "(the bootstrap intervals show how little)")
    return Evaluation(Records(cols), summaries, group_column, factors, bins, tle, cov, enu, n_fixes=n, notes=notes)


def evaluate_points(fixes: Points, truth: Points, *, match: str = "auto", max_distance_m: float = 50.0,
                    fix_id: str | None = None, truth_id: str | None = None, group: str | None = None,
                    extra_factors: tuple[str, ...] = (), image_centre_px: tuple[float, float] | None = None,
                    n_boot: int = 2000, level: float = 0.95, seed: int = 0,
                    cooks_threshold: float | None = None) -> Evaluation:
    """Match ``fixes`` to ``truth`` (``match``: "id", "nearest", or "auto": by id when both files
    carry one, else nearest) and evaluate them."""
    if match not in ("auto", "id", "nearest"):
        raise InputError(f"--match must be id or nearest, got {match!r}")
    if len(truth) == 0:
        raise InputError(f"{truth.path}: no usable truth point", truth.issues)
    fid = fix_id.lower() if fix_id else _first(fixes, FIX_IDS)
    tid = truth_id.lower() if truth_id else _first(truth, TRUTH_IDS)
    for name, pts, given in ((fid, fixes, fix_id), (tid, truth, truth_id)):
        if given and pts.column(name) is None:
            raise InputError(f"{pts.path} has no column {given!r} (its columns: {', '.join(pts.columns)})")
    by_id = E.match_ids(fixes.column(fid), truth.column(tid)) if fid and tid else None
    how = match
    auto_note = ""
    if match == "auto":
        how = "id" if by_id is not None and (by_id.index >= 0).any() else "nearest"
        if by_id is not None and how == "nearest":
            auto_note = (f"no fix id ({fid!r}) equals a truth id ({tid!r}): matched each fix to the nearest truth "
                         f"point within {max_distance_m:g} m instead (--match id to insist)")
    if how == "id":
        if by_id is None:
            which = fixes.path if not fid else truth.path
            raise InputError(f"--match id: {which} has no id column (looked for "
                             f"{', '.join(FIX_IDS if not fid else TRUTH_IDS)}); name it with --fix-id/--truth-id "
                             "or use --match nearest")
        counts = Counter(str(x).strip() for x in truth.column(tid))
        dup = [k for k, c in counts.items() if c > 1]
        if dup:
            raise InputError(f"{truth.path}: truth id {dup[0]!r} is used by {counts[dup[0]]} points; "
                             "ids must be unique to match by id (or use --match nearest)")
        m = by_id
    else:
        if not max_distance_m > 0:
            raise InputError(f"--max-distance must be > 0 m, got {max_distance_m!r}")
        m = E.match_nearest(fixes.lat_deg, fixes.lon_deg, truth.lat_deg, truth.lon_deg,
                            max_distance_m=max_distance_m)
    ok = m.index >= 0
    unmatched = int((~ok).sum())
    example = ""
    if unmatched:
        i = int(np.flatnonzero(~ok)[0])
        example = fixes.place(i) + (f" (id {fixes.column(fid)[i]!r} is not among the truth points)" if how == "id"
                                    else f" ({m.distance_m[i]:.1f} m from the nearest truth point)")
    if not ok.any():
        hint = ("no fix id is among the truth ids: check --fix-id/--truth-id, or use --match nearest" if how == "id"
                else f"no fix lies within {max_distance_m:g} m of a truth point: raise --max-distance or check that "
                     "both files use WGS-84 latitude/longitude (and which column is which)")
        raise InputError(f"{fixes.path}: none of {len(fixes)} fixes matched a point of {truth.path}: {hint}",
                         fixes.issues + truth.issues)
    idx = m.index[ok]
    enu = E.error_enu(fixes.lat_deg[ok], fixes.lon_deg[ok], fixes.h_m[ok], truth.lat_deg[idx], truth.lon_deg[idx],
                      truth.h_m[idx])
    columns = {f"fix_{fixes.unit}": fixes.where[ok]}
    if fid:
        columns["fix_id"] = fixes.column(fid)[ok]
    columns["truth"] = truth.column(tid)[idx] if tid else idx + 1
    if how == "nearest":
        columns["match_distance_m"] = m.distance_m[ok]
        columns["ambiguous"] = m.ambiguous[ok]
    groups = None
    if group:
        if fixes.column(group) is not None:
            groups = fixes.column(group)[ok]
        elif truth.column(group) is not None:
            groups = truth.column(group)[idx]
        else:
            raise InputError(f"--group {group!r}: neither {fixes.path} nor {truth.path} has that column "
                             f"(the fixes have {', '.join(fixes.columns)})")
    factors = _factors(fixes, ok, extra_factors, image_centre_px)
    cov = {k: v[ok] for k in ("sigma_e_m", "sigma_n_m", "rho_en", "sigma_u_m", "cep50_m", "ce90_m", "le90_m")
           if (v := fixes.numeric(k)) is not None}
    ev = evaluate_errors(enu, groups=groups, group_column=group, factors=factors, covariance=cov or None,
                         columns=columns, n_boot=n_boot, level=level, seed=seed, cooks_threshold=cooks_threshold)
    ev.match, ev.n_fixes, ev.unmatched, ev.unmatched_example = how, len(fixes), unmatched, example
    ev.ambiguous = int(m.ambiguous.sum())
    if auto_note:
        ev.notes.insert(0, auto_note)
    ev.not_located = fixes.not_located
    ev.issues = fixes.issues + truth.issues
    if how == "nearest" and ev.ambiguous:
        ev.notes.append(f"{ev.ambiguous} fixes lie less than twice as far from their nearest truth point as from "
                        "the next one: their match may be wrong (the 'ambiguous' column); match by id if the files "
                        "carry one")
    if not fixes.has_heights() or not truth.has_heights():
        which = fixes.path if not fixes.has_heights() else truth.path
        ev.notes.append(f"{which} gives no heights: the vertical statistics are empty")
    return ev


def _factors(fixes: Points, ok: np.ndarray, extra: tuple[str, ...], centre) -> dict[str, tuple[str, np.ndarray]]:
    out = {}
    for name, (label, names) in FACTORS.items():
        col = next((v for n in names if (v := fixes.numeric(n)) is not None), None)
        if col is not None:
            out[name] = (label, col[ok])
    if "pixel_radius_px" not in out and centre is not None:
        u, v = fixes.numeric("u_px"), fixes.numeric("v_px")
        if u is not None and v is not None:
            out["pixel_radius_px"] = (FACTORS["pixel_radius_px"][0], np.hypot(u - centre[0], v - centre[1])[ok])
    for name in extra:
        col = fixes.numeric(name)
        if col is None:
            raise InputError(f"--factor {name!r}: {fixes.path} has no numeric column of that name (its columns: "
                             f"{', '.join(fixes.columns)})")
        out[name.lower()] = (name, col[ok])
    return out


def evaluate_job(fixes_path, truth_path, *, fix_columns: tuple[str, ...] | None = None,
                 truth_columns: tuple[str, ...] | None = None, **kwargs) -> Evaluation:
    """Read both files (any of CSV, GeoJSON, KML, CoT) and :func:`evaluate_points` them."""
    fixes = read_points(fixes_path, columns=fix_columns, what="fix")
    truth = read_points(truth_path, columns=truth_columns, what="truth")
    if len(fixes) == 0:
        raise InputError(f"{fixes_path}: no usable fix to evaluate"
                         + (f" ({sum(fixes.not_located.values())} not located)" if fixes.not_located else ""),
                         fixes.issues)
    ev = evaluate_points(fixes, truth, **kwargs)
    ev.inputs = {"fixes": str(fixes_path), "truth": str(truth_path)}
    return ev


def summary_rows(ev: Evaluation) -> list[dict]:
    """One row per group (``all`` first) with every statistic and its interval."""
    rows = []
    for label, s in ev.summaries.items():
        row = {"group": label, **s.row()}
        fit = ev.tle.get(label)
        if fit is not None:
            row.update({f"tle_{k}": v for k, v in fit.row().items()})
        rows.append(row)
    return rows


def report_dict(ev: Evaluation) -> dict:
    """The evaluation as one JSON-ready document (NaN as null by the caller's json_safe)."""
    out = {"inputs": ev.inputs, "match": ev.match, "fixes": ev.n_fixes, "matched": ev.overall.n,
           "unmatched": ev.unmatched, "ambiguous": ev.ambiguous, "not_located": dict(ev.not_located),
           "level": ev.overall.level, "bootstrap": {"replicates": ev.overall.n_boot, "seed": ev.overall.seed,
                                                    "method": "percentile"},
           "summary": summary_rows(ev),
           "bins": {k: [dataclasses.asdict(b) for b in v] for k, v in ev.bins.items()}, "notes": ev.notes}
    if ev.coverage is not None:
        c = ev.coverage
        out["coverage"] = {"n": c.n, "scale": c.scale, "nominal": c.nominal.tolist(), "observed": c.observed.tolist(),
                           "low": c.low.tolist(), "high": c.high.tolist(),
                           "circles": {k: {"nominal": v[0], "observed": v[1], "low": v[2], "high": v[3], "n": v[4],
                                           "verdict": c.verdict(v[1], v[2], v[3], v[0])}
                                       for k, v in c.circles.items()}}
    return out


def write_evaluation(ev: Evaluation, out_dir, *, stem: str = "evaluation", plots: bool = True) -> list[Path]:
    """``<stem>_points.csv`` (per point), ``<stem>_summary.csv`` (per group), ``<stem>.json`` and,
    with ``plots``, ``<stem>.png`` (errors, error against each factor, coverage)."""
    import json

    from ..accuracy.plots import save_figure
    from ..io.export import json_safe
    from ..io.writers import write_layer

    out = Path(out_dir)
    written = write_layer(out, f"{stem}_points", ev.rows, ["csv"])
    written += write_layer(out, f"{stem}_summary", summary_rows(ev), ["csv"])
    js = out / f"{stem}.json"
    js.write_text(json.dumps(json_safe(report_dict(ev)), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    written.append(js)
    if plots:
        for name, fig in figures(ev).items():
            written.append(save_figure(fig, out / f"{stem}_{name}.png"))
    return written


def figures(ev: Evaluation, *, title: str = "") -> dict:
    """The evaluation's pictures by name: errors, factors (when any), coverage (when the fixes
    carry a covariance)."""
    from ..accuracy.plots import coverage_figure, error_figure, factor_figure

    prefix = f"{title}: " if title else ""
    out = {"errors": error_figure(ev.enu_m, ev.overall, title=f"{prefix}errors against the surveyed points")}
    if ev.factors:
        out["factors"] = factor_figure(ev.factors, np.hypot(ev.enu_m[:, 0], ev.enu_m[:, 1]), ev.bins,
                                       ev.tle.get("all"), title=f"{prefix}horizontal error against the geometry")
    if ev.coverage is not None:
        out["coverage"] = coverage_figure(ev.coverage)
    return out


@dataclass(frozen=True)
class TableData:
    """A table as data: what the CLI prints (eoloc.cli.render.rich_table) and the report writes."""

    title: str
    header: list[str]
    rows: list[list[str]]
    caption: str = ""
    align: str = ""  # per column "l" or "r"; default: the first left, the rest right

    def alignment(self) -> str:
        return (self.align or "l").ljust(len(self.header), "r")


def _num(x: float, fmt: str = ".2f") -> str:
    return "—" if not np.isfinite(x) else format(x, fmt)


def _interval(lo: float, hi: float) -> str:
    return "—" if not (np.isfinite(lo) and np.isfinite(hi)) else f"{lo:.2f} – {hi:.2f}"


def statistics_table(s: E.Summary, title: str) -> TableData:
    pct = f"{s.level:.0%}"
    rows = [[label, _num(s.value[k]), _interval(s.low[k], s.high[k]), what]
            for k, (label, what) in E.STATISTICS.items()]
    rows.append(["CEP (bivariate normal)", _num(s.cep_parametric_m), "",
                 f"[Z15]: sigma E {_num(s.sigma_e_m)}, N {_num(s.sigma_n_m)}, rho {_num(s.rho_en, '+.2f')}"])
    return TableData(title, ["statistic", "value (m)", f"{pct} interval", "what it is"], rows,
                     f"{pct} percentile-bootstrap intervals ({s.n_boot} resamples, seed {s.seed}); errors are fix "
                     "minus truth", align="lrrl")


def evaluation_tables(ev: Evaluation, title: str = "") -> list[TableData]:
    """The evaluation's tables: statistics with intervals, by group, the TLE model, the coverage."""
    prefix = f"{title}: " if title else ""
    out = [statistics_table(ev.overall, f"{prefix}accuracy of {ev.overall.n} fixes against the surveyed points")]
    groups = {k: v for k, v in ev.summaries.items() if k != "all"}
    if groups:
        keys = ("cep50_m", "ce90_m", "le90_m", "mae_h_m", "rmse_h_m", "bias_e_m", "bias_n_m", "bias_u_m")
        out.append(TableData(f"{prefix}by {ev.group_column}", ["group", "n", "CEP", "CE90", "LE90", "MAE h", "RMSE h",
                                                              "bias E", "bias N", "bias U"],
                             [[k, str(x.n), *(_num(x.value[q]) for q in keys)] for k, x in groups.items()],
                             "metres; every interval in the summary CSV"))
    fits = {k: f for k, f in ev.tle.items() if f is not None}
    if fits:
        out.append(TableData(f"{prefix}linear target-location-error model: horizontal error = a + b × slant range",
                             ["group", "n", "removed", "a (m)", "b (m/km)", "R²", "p (slope)", "residual sd (m)"],
                             [[k, str(f.n), str(f.n_removed), f"{f.intercept:.2f} ± {f.intercept_se:.2f}",
                               f"{f.slope * 1000:.3f} ± {f.slope_se * 1000:.3f}", f"{f.r2:.3f}", f"{f.p_slope:.2g}",
                               _num(f.residual_sd)] for k, f in fits.items()],
                             "least squares after removing the points whose Cook's distance exceeds "
                             f"{fits.get('all', next(iter(fits.values()))).threshold:.3g}; ± one standard error"))
    c = ev.coverage
    if c is not None:
        rows = [[f"own {name}", f"{p:.0%}", f"{obs:.1%}", f"{lo:.1%} – {hi:.1%}", c.verdict(obs, lo, hi, p)]
                for name, (p, obs, lo, hi, _n) in c.circles.items()]
        for p in (0.5, 0.9):
            i = int(np.argmin(np.abs(c.nominal - p)))
            rows.append([f"own {p:.0%} ellipse", f"{p:.0%}", f"{c.observed[i]:.1%}",
                         f"{c.low[i]:.1%} – {c.high[i]:.1%}", c.verdict(c.observed[i], c.low[i], c.high[i], p)])
        out.append(TableData(f"{prefix}is the predicted uncertainty honest? ({c.n} fixes with a covariance)",
                             ["region", "predicted", "observed inside", "95 % interval", "verdict"], rows,
                             f"Clopper-Pearson intervals; sigma scale factor {c.scale:.2f} (1 = honest)", "lrrrl"))
    return out


def evaluation_notes(ev: Evaluation) -> list[str]:
    """What the tables do not say: matching, what was left out and why, small samples."""
    notes = []
    if ev.match != "paired":
        notes.append(f"matched by {ev.match}: {ev.overall.n} of {ev.n_fixes} fixes"
                     + (f"; {ev.unmatched} unmatched, e.g. {ev.unmatched_example}" if ev.unmatched else ""))
    if ev.not_located:
        notes.append(f"{sum(ev.not_located.values())} records were not located and are not in the statistics ("
                     + ", ".join(f"{k} {v}" for k, v in ev.not_located.most_common()) + ")")
    return notes + list(ev.notes)
