"""Pictures of an accuracy analysis (matplotlib, written straight to PNG; no GUI backend needed).

- :func:`plot_scatter`: the east/north error cloud of one target with its CEP circles around the
  true point (empirical and bivariate-normal), the mean (systematic part) and the 2-sigma ellipse
  about it (random part) - [Z15] Fig. 7.
- :func:`plot_sweep`: CEP against the gimbal angle, one curve per relief sigma, ellipsoid vs DEM
  side by side - [Q] Fig. 10.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .cep import error_ellipse
from .montecarlo import MonteCarloResult
from .sweep import SweepPoint


def _figure(width: float, height: float):
    from matplotlib.figure import Figure  # a bare Figure: no pyplot state, no display needed

    return Figure(figsize=(width, height), dpi=110, layout="constrained")


def _circle(ax, r: float, centre=(0.0, 0.0), **kw) -> None:
    t = np.linspace(0.0, 2.0 * np.pi, 361)
    ax.plot(centre[0] + r * np.cos(t), centre[1] + r * np.sin(t), **kw)


def _ellipse(ax, cov: np.ndarray, centre, p: float, **kw) -> None:
    a, b, az = error_ellipse(cov, p)
    t = np.linspace(0.0, 2.0 * np.pi, 361)
    th = np.radians(az)  # azimuth from north, clockwise: major axis direction (east, north) = (sin, cos)
    major, minor = np.array([np.sin(th), np.cos(th)]), np.array([np.cos(th), -np.sin(th)])
    pts = centre[:, None] + a * np.cos(t) * major[:, None] + b * np.sin(t) * minor[:, None]
    ax.plot(pts[0], pts[1], **kw)


def plot_scatter(result: MonteCarloResult, path: str | Path, *, target: int = 0, max_points: int = 20_000) -> Path:
    """PNG of target ``target``'s horizontal errors (needs ``monte_carlo(..., keep_samples=True)``)."""
    if result.enu is None:
        raise ValueError("the scatter plot needs the samples: run monte_carlo(..., keep_samples=True)")
    st = result.stats[target]
    e = result.enu[:, target, 0]
    n = result.enu[:, target, 1]
    ok = np.isfinite(e) & np.isfinite(n)
    e, n = e[ok], n[ok]
    step = max(1, e.size // max_points)
    fig = _figure(6.4, 6.0)
    ax = fig.add_subplot()
    ax.scatter(e[::step], n[::step], s=3, alpha=0.35, color="tab:blue", linewidths=0,
               label=f"{e[::step].size:,} of {e.size:,} samples")
    ax.plot([0], [0], marker="+", color="black", markersize=14, mew=2, ls="none", label="true point")
    mean = np.array(st.bias_enu[:2])
    ax.plot(*mean, marker="x", color="tab:red", markersize=10, mew=2, ls="none",
            label=f"mean (systematic) {np.hypot(*mean):.3g} m")
    _circle(ax, st.cep50, color="tab:green", lw=2, label=f"CEP50 empirical {st.cep50:.3g} m")
    _circle(ax, st.cep50_parametric, color="tab:orange", lw=1.5, ls="--",
            label=f"CEP50 bivariate normal {st.cep50_parametric:.3g} m")
    _circle(ax, st.ce90, color="tab:purple", lw=1, ls=":", label=f"CE90 {st.ce90:.3g} m")
    _ellipse(ax, np.cov(e, n), mean, 0.95, color="tab:red", lw=1,
             label=f"95 % ellipse (random: σe {st.sigma_enu[0]:.3g}, σn {st.sigma_enu[1]:.3g} m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east error (m)")
    ax.set_ylabel("north error (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    ax.set_title(f"{result.scenario.name}, target {target}: {result.n:,} samples, seed {result.seed}", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_sweep(points: Sequence[SweepPoint], path: str | Path, *, metric: str = "cep50_m", title: str = "") -> Path:
    """PNG of ``metric`` (a SweepPoint field, default the empirical CEP50) against the angle: one
    panel per method, one curve per relief sigma, a common logarithmic axis."""
    methods = [m for m in ("ellipsoid", "dem") if any(p.method == m for p in points)]
    sigmas = sorted({p.terrain_sigma_m for p in points})
    fig = _figure(5.0 * len(methods) + 1.0, 4.6)
    axes = fig.subplots(1, len(methods), sharey=True, squeeze=False)[0]
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    label = {"cep50_m": "CEP50 (m)", "drms_m": "DRMS (m)", "ce90_m": "CE90 (m)", "sigma_h_m": "σ h (m)"}.get(metric,
                                                                                                          metric)
    for ax, m in zip(axes, methods, strict=True):
        for i, s in enumerate(sigmas):
            pts = sorted((p for p in points if p.method == m and p.terrain_sigma_m == s), key=lambda p: p.angle_deg)
            ax.plot([p.angle_deg for p in pts], [getattr(p, metric) for p in pts], marker="o", ms=3,
                    color=cmap(i / max(1, len(sigmas) - 1)), label=f"relief σ {s:g} m")
        ax.set_yscale("log")
        ax.set_xlabel("gimbal angle (deg)")
        ax.set_title({"ellipsoid": "ellipsoid at the mean height (relief as error)",
                      "dem": "DEM (M4 on the relief)"}[m], fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel(label)
    axes[-1].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=11)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_compensation(oblique_deg: np.ndarray, before_en: np.ndarray, after_en: dict[str, np.ndarray], rows,
                      path: str | Path, *, title: str = "location error against oblique angle") -> Path:
    """PNG of :func:`compensation_figure`."""
    return save_figure(compensation_figure(oblique_deg, before_en, after_en, rows, title=title), path)


def compensation_figure(oblique_deg: np.ndarray, before_en: np.ndarray, after_en: dict[str, np.ndarray], rows, *,
                        title: str = "location error against oblique angle"):
    """[P] Fig. 1 with and without compensation: each fix's horizontal error against its
    oblique angle (left), and CEP50 by oblique band before and after (right, log scale). ``rows``:
    :func:`eoloc.accuracy.compensation.band_table` rows."""
    fig = _figure(11.0, 4.4)
    ax, bx = fig.subplots(1, 2)
    ob = np.ravel(oblique_deg)
    r0 = np.hypot(*np.asarray(before_en).reshape(-1, 2).T)
    ax.scatter(ob, r0, s=4, c="0.6", label="located", rasterized=True)
    colours = ("tab:blue", "tab:green", "tab:orange", "tab:purple")
    for (name, e), c in zip(after_en.items(), colours, strict=False):
        ax.scatter(ob, np.hypot(*np.asarray(e).reshape(-1, 2).T), s=4, c=c, label=f"compensated ({name})",
                   rasterized=True)
    ax.set_yscale("log")
    ax.set_xlabel("oblique angle (deg from the vertical)")
    ax.set_ylabel("horizontal error (m)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper left", fontsize=8, markerscale=3)
    bands = [r for r in rows if not r.summary]
    x = np.arange(len(bands))
    width = 0.8 / (1 + len(after_en))
    bx.bar(x - 0.4 + width / 2, [r.cep_before_m for r in bands], width, color="0.6", label="located")
    for k, (name, c) in enumerate(zip(after_en, colours, strict=False)):
        bx.bar(x - 0.4 + width * (k + 1.5), [r.cep_after_m[name] for r in bands], width, color=c,
               label=f"compensated ({name})")
    bx.set_xticks(x, [f"{r.lo_deg:.0f}–{r.hi_deg:.0f}°\nn={r.n}" for r in bands], fontsize=8)
    bx.set_yscale("log")
    bx.set_ylabel("CEP50 (m)")
    bx.set_xlabel("oblique band")
    bx.grid(True, axis="y", which="both", alpha=0.3)
    bx.legend(fontsize=8)
    fig.suptitle(title)
    return fig


# -- accuracy against surveyed points (eoloc evaluate / eoloc report) ------------------------------


def save_figure(fig, path: str | Path) -> Path:
    """Write a figure as PNG (creating the folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def figure_png(fig) -> bytes:
    """A figure as PNG bytes (for pages that carry their pictures inline)."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def error_figure(enu_m: np.ndarray, summary, *, title: str = "errors against the surveyed points"):
    """East/north scatter of the errors with the CEP and CE90 circles about the true point and the
    mean (bias); beside it the vertical errors' histogram with ±LE90. ``summary``: an
    :class:`eoloc.accuracy.evaluation.Summary` of the same errors."""
    fig = _figure(10.5, 4.6)
    ax, bx = fig.subplots(1, 2, width_ratios=(1.1, 1.0))
    enu = np.asarray(enu_m, dtype=np.float64).reshape(-1, 3)
    ax.scatter(enu[:, 0], enu[:, 1], s=9, c="tab:blue", alpha=0.6, label=f"fixes (n={summary.n})", rasterized=True)
    v = summary.value
    for key, colour, label in (("cep50_m", "tab:green", "CEP"), ("ce90_m", "tab:red", "CE90")):
        if np.isfinite(v[key]):
            _circle(ax, v[key], color=colour, lw=1.6, label=f"{label} {v[key]:.2f} m")
    if np.isfinite(v["bias_e_m"]):
        ax.plot([v["bias_e_m"]], [v["bias_n_m"]], marker="x", ms=11, mew=2.5, color="k",
                label=f"mean ({v['bias_e_m']:+.2f}, {v['bias_n_m']:+.2f}) m")
    ax.axhline(0, color="0.7", lw=0.8)
    ax.axvline(0, color="0.7", lw=0.8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east error (m)")
    ax.set_ylabel("north error (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    up = enu[np.isfinite(enu[:, 2]), 2]
    if up.size:
        bx.hist(up, bins=max(5, min(40, up.size // 3)), color="tab:purple", alpha=0.75)
        if np.isfinite(v["le90_m"]):
            for s in (-1, 1):
                bx.axvline(s * v["le90_m"], color="tab:red", lw=1.5, label="±LE90" if s > 0 else None)
            bx.legend(fontsize=8)
        bx.set_xlabel("vertical error (m)")
        bx.set_ylabel("fixes")
    else:
        bx.text(0.5, 0.5, "no heights: no vertical errors", ha="center", va="center", transform=bx.transAxes)
        bx.set_axis_off()
    bx.grid(True, alpha=0.3)
    fig.suptitle(title)
    return fig


def factor_figure(factors: dict, horizontal_m: np.ndarray, bins: dict, tle=None, *,
                  title: str = "horizontal error against the geometry"):
    """One panel per factor (name -> (label, values)): each fix's horizontal error against the
    factor, the median and 90 % error per bin and, on slant range, the linear TLE model with the
    points Cook's distance removed marked."""
    names = list(factors)
    cols = min(3, len(names))
    rows = -(-len(names) // cols)
    fig = _figure(4.2 * cols, 3.5 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    r = np.asarray(horizontal_m, dtype=np.float64)
    for ax, name in zip(axes, names, strict=False):
        label, x = factors[name]
        x = np.asarray(x, dtype=np.float64)
        ax.scatter(x, r, s=7, c="0.45", alpha=0.55, rasterized=True, label="fixes")
        b = bins.get(name) or []
        if b:
            mid = [(q.lo + q.hi) / 2 for q in b]
            ax.plot(mid, [q.cep50_m for q in b], "o-", color="tab:green", label="median per bin")
            ax.plot(mid, [q.ce90_m for q in b], "s--", color="tab:red", label="90 % per bin")
        if name == "range_m" and tle is not None:
            xs = np.linspace(np.nanmin(x), np.nanmax(x), 50)
            ax.plot(xs, tle.intercept + tle.slope * xs, color="tab:blue", lw=2,
                    label=f"TLE {tle.intercept:.2f} m + {tle.slope * 1000:.3f} m/km")
            out = np.isfinite(tle.cooks) & ~tle.kept
            if out.any():
                ax.scatter(x[out], r[out], s=40, facecolors="none", edgecolors="tab:orange",
                           label=f"Cook's D > {tle.threshold:.3g} ({int(out.sum())})")
        ax.set_xlabel(label)
        ax.set_ylabel("horizontal error (m)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    for ax in axes[len(names):]:
        ax.set_axis_off()
    fig.suptitle(title)
    return fig


def coverage_figure(cov, *, title: str = "predicted against observed: is the uncertainty honest?"):
    """Calibration plot of a :class:`eoloc.accuracy.evaluation.Coverage`: the share of truth points
    inside each fix's own p-ellipse against p, with its 95 % Clopper-Pearson band; the CE50/CE90
    circles and LE90 as points. An honest uncertainty follows the diagonal."""
    fig = _figure(6.0, 5.0)
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], color="0.5", lw=1, ls="--", label="honest")
    ax.fill_between(cov.nominal, cov.low, cov.high, color="tab:blue", alpha=0.2, label="95 % interval")
    ax.plot(cov.nominal, cov.observed, "o-", color="tab:blue", ms=4, label=f"inside own ellipse (n={cov.n})")
    marks = {"CE50": "s", "CE90": "D", "LE90": "^"}
    for name, (p, obs, lo, hi, _n) in cov.circles.items():
        if np.isfinite(obs):
            ax.errorbar([p], [obs], yerr=[[obs - lo], [hi - obs]], fmt=marks.get(name, "o"), ms=8, capsize=3,
                        label=f"inside own {name}: {obs:.0%}")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel("predicted probability")
    ax.set_ylabel("observed share of truth points inside")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(f"{title}\nsigma scale factor {cov.scale:.2f} (1 = honest)", fontsize=10)
    return fig


def plot_flight_accuracy(fa, path: str | Path) -> Path:
    """The accuracy of a flight (:class:`eoloc.sequence.flight.FlightAccuracy`): left, each target's
    first-order CE90 as the share of its biases, Gauss–Markov errors and noise (stacked by variance,
    so the bar's length is the CE90) with the Monte Carlo CE90 as a diamond and one fix's CE90 as a
    bar; right, every fix's CE90 over time, first order and Monte Carlo, per target."""
    fig = _figure(11.0, 4.6)
    ax, bx = fig.subplots(1, 2)
    rows = [r for r in fa.targets if r.get("status") == "OK"]
    colours = {"bias": "tab:red", "markov": "tab:orange", "noise": "tab:blue"}
    labels = {"bias": "biases (never average)", "markov": "Gauss–Markov", "noise": "noise"}
    for i, r in enumerate(rows):
        parts = np.array([r[f"ce90_{k}_m"] ** 2 for k in colours])
        total = r["ce90_m"]
        share = parts / parts.sum() * total if parts.sum() > 0 else parts
        left = 0.0
        for (k, c), w in zip(colours.items(), share, strict=True):
            ax.barh(i, w, left=left, height=0.5, color=c, label=labels[k] if i == 0 else None)
            left += w
        ax.plot([r["mc_ce90_m"]], [i], "D", color="k", label="Monte Carlo CE90" if i == 0 else None)
        ax.plot([r["single_fix_ce90_m"]], [i], "|", color="0.4", ms=18, mew=2,
                label="one fix's CE90" if i == 0 else None)
    ax.set_yticks(range(len(rows)), [r["target_id"] for r in rows])
    ax.set_ylim(-0.75, max(len(rows), 2) - 0.25)
    ax.set_xlabel("CE90 of the target's estimate (m)")
    ax.set_xscale("symlog", linthresh=1.0)
    ax.grid(True, axis="x", alpha=0.3)
    if rows:
        ax.legend(fontsize=8, loc="lower right")
    flagged = [r["target_id"] for r in fa.targets if r.get("status") not in ("OK", None)]
    ax.set_title("targets" + (f" (no estimate: {', '.join(flagged)})" if flagged else ""), fontsize=10)
    by = {}
    for r in fa.fixes:
        if r.get("status") == "OK":
            by.setdefault(r["target_id"], []).append(r)
    for tid, fr in sorted(by.items()):
        t = [r["time_s"] for r in fr]
        line, = bx.plot(t, [r["ce90_m"] for r in fr], "-", lw=1.2, label=f"{tid} first order")
        bx.plot(t, [r["mc_ce90_m"] for r in fr], "o", ms=3, color=line.get_color(), label=f"{tid} Monte Carlo")
    bx.set_xlabel("time (s)")
    bx.set_ylabel("CE90 of one fix (m; Monte Carlo far above first order: not linear there)")
    bx.set_yscale("log")
    bx.grid(True, alpha=0.3)
    bx.legend(fontsize=7, ncol=2)
    bx.set_title(f"every fix ({fa.samples:,} copies of the flight)", fontsize=10)
    fig.savefig(path)
    return Path(path)
