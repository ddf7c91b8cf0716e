"""The `eoloc accuracy` and `eoloc sweep` jobs: a scenario from a config or a built-in one, run by
Monte Carlo here or on Dask."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

from ..errors import InputError


@dataclass
class AccuracyJob:
    """The Monte Carlo result, one row per target (the figures of accuracy.csv) and, when asked,
    the sensitivity of each source alone."""

    result: object
    rows: list[dict]
    sensitivity: list = field(default_factory=list)


def scenario_from(config_path, scenario, samples, seed, default_n=None):
    """(scenario, samples, seed) from a config's [accuracy] section or a built-in scenario."""
    from ..accuracy import SCENARIOS
    from ..io.config import load_config
    from .setup import accuracy_scenario

    if (config_path is None) == (scenario is None):
        raise InputError("give a CONFIG file with an [accuracy] section, or --scenario s13|q-ellipsoid|q-dem")
    if scenario is not None:
        n = samples or default_n or (1_000_000 if scenario == "s13" else 5000)
        return SCENARIOS[scenario](), n, (0 if seed is None else seed)
    cfg = load_config(config_path)
    scn = accuracy_scenario(cfg, config_path)
    return scn, samples or default_n or cfg.accuracy.samples, (cfg.accuracy.seed if seed is None else seed)


def mapper(address):
    """A context giving the mapper for --dask ADDRESS (None: compute here)."""
    if address is None:
        return contextlib.nullcontext(None)
    from ..accuracy.runners import dask_mapper

    return dask_mapper(address)


def accuracy_job(scn, n: int, seed: int, *, sensitivity_samples: int = 0, keep_samples: bool = False, mapper=None,
                 progress=None) -> AccuracyJob:
    from ..accuracy import monte_carlo, sensitivity

    result = monte_carlo(scn, n, seed=seed, progress=progress, keep_samples=keep_samples, mapper=mapper)
    rows_s = sensitivity(scn, sensitivity_samples, seed=seed, progress=progress,
                         mapper=mapper) if sensitivity_samples else []
    rows = []
    for k, st in enumerate(result.stats):
        rows.append({"target": k, "truth_lat_deg": st.truth[0], "truth_lon_deg": st.truth[1],
                     "truth_h_m": st.truth[2], "n": st.n, "failed": st.n_failed,
                     "sigma_lat_deg": st.sigma_lat_deg, "sigma_lon_deg": st.sigma_lon_deg,
                     "sigma_h_m": st.sigma_h_m, "bias_e_m": st.bias_enu[0], "bias_n_m": st.bias_enu[1],
                     "bias_u_m": st.bias_enu[2], "sigma_e_m": st.sigma_enu[0], "sigma_n_m": st.sigma_enu[1],
                     "sigma_u_m": st.sigma_enu[2], "rho_en": st.rho_en, "cep50_m": st.cep50,
                     "cep50_parametric_m": st.cep50_parametric, "ce90_m": st.ce90, "le90_m": st.le90,
                     "drms_m": st.drms, "ellipse_major_m": st.ellipse[0], "ellipse_minor_m": st.ellipse[1],
                     "ellipse_azimuth_deg": st.ellipse[2]})
    return AccuracyJob(result, rows, rows_s)
