"""What a job builds from a configuration: the error budget of per-fix covariance, the learned
compensation model, the Monte Carlo scenario (opening the DEM it names). The config module only
reads and validates the file; these turn its sections into the library's objects."""

from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError, ModelFileError
from ..io.config import Config


def accuracy_scenario(cfg: Config, path: str | Path, *, rule=None, dem_crs: str | None = None):
    """The Monte Carlo scenario of a config's [accuracy] section (DEM paths relative to the file);
    ``rule``: a stop rule replacing the config's (the command line's); ``dem_crs``: the CRS of
    the config's DEM files that carry none, replacing its ``dem_crs``."""
    from ..accuracy.budget import ErrorBudget
    from ..accuracy.montecarlo import Scenario
    from ..rules.spec import rule_from_table
    from ..sensor import Pose
    from ..terrain import open_dem

    a = cfg.accuracy
    if a is None:
        raise ConfigError(f"config file {str(path)!r} has no [accuracy] section (pose, stop rule, budget); "
                          "see the README, or use --scenario for a built-in one")
    missing = [k for k in ("pose", "stop") if getattr(a, k) is None and not (k == "stop" and rule is not None)]
    if missing:
        raise ConfigError(f"config file {str(path)!r}: [accuracy] needs {' and '.join(missing)} for a Monte Carlo "
                          "run (the nominal observation); see the README")
    p = a.pose
    if rule is None:  # [accuracy.stop]: one key names the rule and holds its value (DEM files: opened here)
        st = a.stop
        rule = rule_from_table(st, lambda files: open_dem([Path(path).parent / d for d in files],
                                                          vertical=st.dem_vertical, assume_crs=dem_crs or st.dem_crs))
    return Scenario(Path(path).stem, cfg.sensor(),
                    Pose(p.lat_deg, p.lon_deg, p.h_m, p.yaw_deg, p.pitch_deg, p.roll_deg, tuple(p.gimbal_deg)),
                    ErrorBudget.from_mapping(a.budget), rule,
                    pixels=None if a.pixels is None else a.pixels, velocity_ned_mps=a.velocity_ned_mps)


def optional_budget(cfg: Config | None):
    """The config's [accuracy.budget] as an ErrorBudget, None without a config or without the
    section (the jobs where a budget only adds the uncertainty columns)."""
    from ..accuracy.budget import ErrorBudget

    return ErrorBudget.from_mapping(cfg.accuracy.budget) if cfg is not None and cfg.accuracy is not None else None


def error_budget(cfg: Config, path: str | Path):
    """The config's [accuracy.budget] as an ErrorBudget (for per-fix covariance)."""
    from ..accuracy.budget import ErrorBudget

    if cfg.accuracy is None:
        raise ConfigError(f"config file {str(path)!r} has no [accuracy.budget] section: list the error sources, "
                          "e.g. yaw_deg = {normal = 0.02}; see the README")
    return ErrorBudget.from_mapping(cfg.accuracy.budget)


def compensation_model(cfg: Config, path: str | Path, override: str | Path | None = None):
    """The compensation model of ``--compensate`` (``override``) or of the config's [compensation]
    (its path relative to the config file), checked against the config's feature set; None if
    neither names one."""
    c = cfg.compensation
    if override is None and c is None:
        return None
    from ..accuracy.compensation import CompensationModel  # scipy: only when there is a model

    model_path = Path(override) if override is not None else Path(path).parent / c.model
    try:
        return CompensationModel.load(model_path, features=None if c is None else c.features)
    except ModelFileError as exc:
        raise ConfigError(str(exc)) from None


def misb_setup(cfg: Config | None):
    """(sensor, error budget) for a KLV stream: the MISB sensor with the config's [installation]
    and its [accuracy.budget]; (None, None) without a config (the defaults of the KLV jobs)."""
    if cfg is None:
        return None, None
    from ..ground.frame import misb_sensor

    inst = cfg.installation
    sensor = misb_sensor(inst.mount_misalignment_deg, inst.boresight_misalignment_deg, inst.lever_arm_m)
    return sensor, optional_budget(cfg)
