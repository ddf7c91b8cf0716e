"""The `eoloc accuracy` and `eoloc sweep` jobs: a scenario from a config or a built-in one, run by
Monte Carlo here or on Dask; and the accuracy of a flight flown (telemetry + detections)."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..rules import OnDEM


@dataclass
class AccuracyJob:
    """The Monte Carlo result, one row per target (the figures of accuracy.csv) and, when asked,
    the sensitivity of each source alone."""

    result: object
    rows: list[dict]
    sensitivity: list = field(default_factory=list)


def scenario_from(config_path, scenario, samples, seed, default_n=None, *, rule=None, dem_crs=None):
    """(scenario, samples, seed) from a config's [accuracy] section or a built-in scenario;
    ``rule`` replaces the scenario's stop rule, ``dem_crs`` is the CRS of the config's DEM files
    that carry none (:func:`eoloc.jobs.setup.accuracy_scenario`)."""
    from ..accuracy import SCENARIOS
    from ..io.config import load_config
    from .setup import accuracy_scenario

    if (config_path is None) == (scenario is None):
        raise InputError("give a CONFIG file with an [accuracy] section, or --scenario s13|q-ellipsoid|q-dem")
    if scenario is not None:
        n = samples or default_n or (1_000_000 if scenario == "s13" else 5000)
        scn = SCENARIOS[scenario]()
        return (scn if rule is None else replace(scn, rule=rule)), n, (0 if seed is None else seed)
    cfg = load_config(config_path)
    scn = accuracy_scenario(cfg, config_path, rule=rule, dem_crs=dem_crs)
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


def flight_job(cfg, config_path, telemetry, detections, rule, *, samples: int, seed: int, progress=None, **pairing):
    """The accuracy of every fix and target of a flight (:func:`eoloc.sequence.flight.flight_accuracy`):
    the detections located with the config's sensor and budget, then first order and Monte Carlo."""
    from ..sequence.flight import flight_accuracy
    from .sequence import located_detections
    from .setup import error_budget

    if cfg.accuracy is None:
        raise InputError(f"{config_path}: the accuracy of a flight needs the config's [accuracy.budget] (the error "
                         "of every input, and how it behaves in time: see the README, Uncertainty)")
    job = located_detections(cfg, telemetry, detections, rule, **pairing)
    located = job.located
    budget = error_budget(cfg, config_path)
    ok = located.fixes.ok
    idx = np.flatnonzero(ok)
    pose = located.target_pose().take(idx)
    fa = flight_accuracy(cfg.sensor(), pose, (located.pixels[0][idx], located.pixels[1][idx]),
                         rule_at(located.rule, idx), budget,
                         located.fixes.flat(idx), located.covariance.take(idx), located.extra["time_s"][idx],
                         located.extra["target_id"][idx], n=samples, seed=seed, progress=progress)
    return fa, job


def klv_flight_job(cfg, config_path, path, dem, *, samples: int, seed: int, progress=None):
    """:func:`flight_job` of a KLV or MPEG-TS file's VMTI detections (on ``dem``, else each packet's
    frame-centre elevation), with the MISB sensor and the config's [installation] and budget."""
    from ..accuracy.covariance import locate_with_covariance
    from ..io.klv import klv_telemetry, read_klv, vmti_detections
    from ..sequence.flight import flight_accuracy
    from .klvframes import vmti_flight
    from .setup import misb_setup

    sensor, budget = misb_setup(cfg)
    if budget is None:
        raise InputError(f"{config_path}: the accuracy of a flight needs the config's [accuracy.budget]")
    stream = read_klv(path)
    det = vmti_detections(stream)
    if not len(det):
        raise InputError(f"{path}: no ST 0903 VMTI target in the stream: nothing to analyse (the accuracy of a "
                         "flight is that of its located targets)")
    vf = vmti_flight(klv_telemetry(stream), det, None if dem is None else OnDEM(dem), base=sensor)
    fixes, cov = locate_with_covariance(vf.sensor, vf.pose, budget, vf.pixels, vf.rule)
    ok = np.flatnonzero(fixes.ok)
    if ok.size == 0:
        raise InputError(f"{path}: none of the {len(det)} VMTI detections could be located")
    return flight_accuracy(vf.sensor, vf.pose.take(ok), (vf.pixels[0][ok], vf.pixels[1][ok]), rule_at(vf.rule, ok),
                           budget,
                           fixes.flat(ok), cov.take(ok), vf.time_s[ok], vf.target_id[ok], n=samples, seed=seed,
                           progress=progress), stream.issues


def rule_at(rule, index):
    """``rule`` with its per-target values (a range, a height) taken at ``index``; as it is when it
    has one value."""
    field_name = getattr(rule, "value_field", "")
    if field_name and np.ndim(getattr(rule, field_name)):
        from dataclasses import replace

        return replace(rule, **{field_name: getattr(rule, field_name)[index]})
    return rule
