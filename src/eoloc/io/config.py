"""The platform/camera configuration file (TOML), validated on load.

    [camera]                 # one of: focal_mm + pixel_um | hfov_deg | fx (+ fy)
    width = 1024             # pixels
    height = 768
    focal_mm = 50.0
    pixel_um = 5.5
    # cx, cy = principal point in pixels (default: image centre, (W-1)/2, (H-1)/2)

    [camera.distortion]      # optional
    model = "brown-conrady"  # k1, k2, p1, p2, k3 (OpenCV's coefficients, normalised coordinates)
    k1 = -0.28
    # model = "ratio": [Z15]'s distortion-ratio table; field / d_percent (default: [Z15]'s own)

    [gimbal]
    model = "az-el"          # "az-el" | "roll-pitch" | "fixed" (then quaternion = [w,x,y,z] or matrix)

    [installation]           # all optional, default zero
    mount_misalignment_deg = [0.0, 0.0, 0.0]      # gimbal base vs INS, about body x, y, z
    boresight_misalignment_deg = [0.0, 0.0, 0.0]  # optical axis vs gimbal, about camera x, y, z
    lever_arm_m = [0.0, 0.0, 0.0]                 # camera from INS reference, body FRD metres
    # misalignments over 5 deg are refused as a units mistake unless allow_large_misalignment = true

    [telemetry]              # optional corrections of the GPS/INS records (eoloc calibrate writes them)
    heading_bias_deg = 0.0   # INS heading minus true heading: subtracted from every yaw read
    time_offset_s = 0.0      # telemetry clock minus video clock (default of --time-offset)
    time_origin = "unix"     # optional: what time_s = 0 is ("unix" or an ISO 8601 instant); adds time_utc
    msl_geoid = "egm2008.tif"  # optional: geoid grid for h_msl_m telemetry, relative to this file (default EGM96)

    [compensation]           # optional: learned error compensation (eoloc compensate train writes the model)
    model = "compensation.json"   # relative to this file; applied by eoloc locate (or --compensate MODEL)
    features = ["oblique", "azimuth", "height", "bearing"]   # optional: the feature set it must have
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from ..errors import ConfigError
from ..sensor import BrownConrady, Camera, DistortionRatio, SensorModel, gimbal_from_name


class _Strict(BaseModel):
    # nan in a config is a typo; so is `width = true` or `width = "1024"`: no type is coerced (strict),
    # except TOML's integers where a real number is asked and its arrays for tuples (see load_config)
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=True)


SMALL_ANGLE_DEG = 5.0  # misalignments are small corrections; larger ones need allow_large_misalignment


class DistortionConfig(_Strict):
    model: Literal["brown-conrady", "ratio"]
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    field: tuple[float, ...] | None = None
    d_percent: tuple[float, ...] | None = None

    @model_validator(mode="after")
    def _fits_model(self) -> DistortionConfig:
        brown = any(getattr(self, k) != 0.0 for k in ("k1", "k2", "p1", "p2", "k3"))
        if self.model == "ratio" and brown:
            raise ValueError("k1, k2, p1, p2, k3 belong to model = 'brown-conrady', not 'ratio'")
        if self.model == "brown-conrady" and (self.field is not None or self.d_percent is not None):
            raise ValueError("field / d_percent belong to model = 'ratio', not 'brown-conrady'")
        if (self.field is None) != (self.d_percent is None):
            raise ValueError("field and d_percent go together (the distortion table)")
        return self

    def build(self, camera: Camera) -> Camera:
        if self.model == "brown-conrady":
            return camera.with_distortion(BrownConrady(self.k1, self.k2, self.p1, self.p2, self.k3))
        table = {} if self.field is None else {"field": self.field, "d_percent": self.d_percent}
        return camera.with_distortion(DistortionRatio.for_camera(camera, **table))


class CameraConfig(_Strict):
    # the ranges of real cameras, wide: a value outside is a unit mistake (m for mm, mm for µm), and a
    # focal length of 1e-300 would put every pixel at the image centre
    width: int = Field(gt=0, le=200_000, description="image width, pixels")
    height: int = Field(gt=0, le=200_000, description="image height, pixels")
    focal_mm: float | None = Field(None, ge=0.1, le=20_000, description="focal length, mm (0.1 to 20 000)")
    pixel_um: float | None = Field(None, ge=0.05, le=1_000, description="pixel pitch, µm (0.05 to 1000)")
    hfov_deg: float | None = Field(None, ge=1e-3, lt=180)
    fx: float | None = Field(None, ge=1e-3, le=1e8, description="focal length in pixels (0.001 to 1e8)")
    fy: float | None = Field(None, ge=1e-3, le=1e8)
    cx: float | None = Field(None, ge=-2e6, le=2e6, description="principal point, pixels")
    cy: float | None = Field(None, ge=-2e6, le=2e6)
    distortion: DistortionConfig | None = None

    @model_validator(mode="after")
    def _one_focal(self) -> CameraConfig:
        ways = [self.focal_mm is not None or self.pixel_um is not None, self.hfov_deg is not None, self.fx is not None]
        if sum(ways) != 1:
            raise ValueError("give the focal length one way: focal_mm + pixel_um, or hfov_deg, or fx (+ fy)")
        if (self.focal_mm is None) != (self.pixel_um is None):
            raise ValueError("focal_mm and pixel_um go together")
        return self

    def build(self) -> Camera:
        camera = self._pinhole()
        return camera if self.distortion is None else self.distortion.build(camera)

    def _pinhole(self) -> Camera:
        if self.focal_mm is not None:
            return Camera.from_focal_mm(self.focal_mm, self.pixel_um, self.width, self.height, cx=self.cx, cy=self.cy)
        if self.hfov_deg is not None:
            return Camera.from_hfov(self.hfov_deg, self.width, self.height, cx=self.cx, cy=self.cy)
        cx = (self.width - 1) / 2 if self.cx is None else self.cx
        cy = (self.height - 1) / 2 if self.cy is None else self.cy
        return Camera(self.width, self.height, self.fx, self.fy or self.fx, cx, cy)


class GimbalConfig(_Strict):
    model: Literal["az-el", "roll-pitch", "fixed"] = "az-el"
    quaternion: tuple[float, float, float, float] | None = None
    matrix: tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]] | None = None


class InstallationConfig(_Strict):
    mount_misalignment_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    boresight_misalignment_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    allow_large_misalignment: bool = False

    @model_validator(mode="after")
    def _plausible(self) -> InstallationConfig:
        limit = 180.0 if self.allow_large_misalignment else SMALL_ANGLE_DEG
        for key in ("mount_misalignment_deg", "boresight_misalignment_deg"):
            worst = max(abs(a) for a in getattr(self, key))
            if worst > limit:
                fix = ("angles are in degrees, in (-180, 180]" if self.allow_large_misalignment else
                       f"a misalignment is a small correction (<= {SMALL_ANGLE_DEG:g} deg): check the units (degrees, "
                       "not radians or arc-minutes), or model a tilted mount with [gimbal] model = 'fixed'; set "
                       "allow_large_misalignment = true if it really is this large")
                raise ValueError(f"{key} = {list(getattr(self, key))} has {worst:g} deg: {fix}")
        if max(abs(x) for x in self.lever_arm_m) > 100.0:
            raise ValueError(f"lever_arm_m = {list(self.lever_arm_m)}: more than 100 m from the INS; it is in metres")
        return self


class TelemetryConfig(_Strict):
    heading_bias_deg: float = Field(0.0, ge=-180.0, le=180.0)
    time_offset_s: float = Field(0.0, ge=-86400.0, le=86400.0)
    time_origin: str | None = None  # "unix", or the ISO 8601 UTC instant of time_s = 0 (adds time_utc columns)
    msl_geoid: str | None = None  # geoid grid for h_msl_m telemetry (relative to the config file; default EGM96)

    @model_validator(mode="after")
    def _origin(self) -> TelemetryConfig:
        if self.time_origin is not None and self.time_origin != "unix":
            from datetime import datetime

            try:
                t = datetime.fromisoformat(self.time_origin.replace("Z", "+00:00"))
            except ValueError:
                t = None
            if t is None or t.tzinfo is None:
                raise ValueError(f"time_origin = {self.time_origin!r}: give \"unix\" (time_s counts seconds since "
                                 "1970-01-01 UTC) or an ISO 8601 instant with its zone, e.g. "
                                 "\"2026-11-23T09:30:00Z\"")
        return self


class CompensationConfig(_Strict):
    model: str
    features: tuple[str, ...] | None = None


class PoseConfig(_Strict):
    lat_deg: float = Field(ge=-90, le=90)
    lon_deg: float
    h_m: float
    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    gimbal_deg: tuple[float, ...] = ()


def stop_model(name: str, base: type[BaseModel], dem_field: tuple, **extra: tuple) -> type[BaseModel]:
    """The stop rule as a table of one key (:data:`eoloc.rules.spec.SPECS`: ``range_m``,
    ``target_height_m``, ``dem``; exactly one given), each number checked against its rule's
    domain: a config's ``[accuracy.stop]`` and the HTTP API's ``stop`` object. ``dem_field``: the
    DEM key's (type, Field) (files in a config, a served name in the API); ``extra``: more fields."""
    from pydantic import create_model

    from ..rules.spec import SPECS

    keys = [s.key for s in SPECS]

    class OneRule(base):
        @model_validator(mode="after")
        def _one(self):
            if sum(getattr(self, k) is not None for k in keys) != 1:
                raise ValueError(f"give exactly one of {', '.join(keys[:-1])} or {keys[-1]}")
            return self

    fields: dict = {}
    for s in SPECS:
        if s.value == "dem":
            fields[s.key] = dem_field
        else:
            low = {"gt": s.minimum} if s.value == "distance" else {"ge": s.minimum}
            fields[s.key] = (float | None, Field(None, **low, le=s.maximum, description=f"{s.method}: {s.help}"))
    return create_model(name, __base__=OneRule, **fields, **extra)


StopConfig = stop_model(
    "StopConfig", _Strict, (tuple[str, ...] | None, Field(None, description="M4: DEM files, relative to the config")),
    dem_vertical=(Literal["egm96", "egm2008", "ellipsoid"], "egm96"),
    dem_crs=(str | None, None))  # the CRS of a DEM file that carries none (ESRI ASCII), as --dem-crs


class AccuracyConfig(_Strict):
    """[accuracy]: the error budget (per-fix covariance: eoloc locate --covariance) and, for Monte
    Carlo (eoloc accuracy CONFIG), the nominal observation: pose and ``[accuracy.stop]``, the stop
    rule as one key (``range_m``, ``target_height_m`` or ``dem``)."""

    pose: PoseConfig | None = None
    stop: StopConfig | None = None
    pixels: tuple[tuple[float, float], ...] | None = None
    velocity_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    samples: int = Field(100_000, ge=2)
    seed: int = 0
    budget: dict[str, dict[str, float | str]]

    @model_validator(mode="before")
    @classmethod
    def _stop_table(cls, data):
        if isinstance(data, dict) and isinstance(data.get("stop"), str):
            raise ValueError(f"stop = {data['stop']!r}: the stop rule is a table of one key, e.g. [accuracy.stop] "
                             "range_m = 10200 (or target_height_m = H, or dem = [\"tile.tif\"])")
        return data

    @model_validator(mode="after")
    def _budget(self) -> AccuracyConfig:
        from ..accuracy.budget import ErrorBudget

        ErrorBudget.from_mapping(self.budget)  # names and laws checked here, with the key in the message
        return self


class Config(_Strict):
    camera: CameraConfig | None = None  # absent where the inputs bring their own (KLV, drone photos)
    _path: str = PrivateAttr("")  # the file it was read from, for messages
    gimbal: GimbalConfig = GimbalConfig()
    installation: InstallationConfig = InstallationConfig()
    telemetry: TelemetryConfig = TelemetryConfig()
    accuracy: AccuracyConfig | None = None
    compensation: CompensationConfig | None = None

    def sensor(self) -> SensorModel:
        """The SensorModel this configuration describes."""
        extra = {}
        if self.gimbal.model == "fixed":
            extra = {"quaternion": self.gimbal.quaternion, "matrix": self.gimbal.matrix}
        elif self.gimbal.quaternion is not None or self.gimbal.matrix is not None:
            raise ConfigError(f"gimbal.quaternion/matrix only apply to model = 'fixed', not {self.gimbal.model!r}")
        if self.camera is None:
            where = f"config file {self._path!r}" if self._path else "the config"
            raise ConfigError(f"{where} has no [camera] section (width, height, and hfov_deg or focal_px): this "
                              "command takes the camera's geometry from it")
        return SensorModel(self.camera.build(), gimbal_from_name(self.gimbal.model, **extra),
                           self.installation.mount_misalignment_deg, self.installation.boresight_misalignment_deg,
                           self.installation.lever_arm_m)


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration; errors name the file and the key."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"config file {str(path)!r} does not exist (check the path)") from None
    except IsADirectoryError:
        raise ConfigError(f"config file {str(path)!r} is a folder: give the TOML file in it") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"config file {str(path)!r} is not UTF-8 (byte 0x{exc.object[exc.start]:02X} at offset "
                          f"{exc.start}): save it as UTF-8") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {str(path)!r} is not valid TOML: {exc}") from None
    try:
        raw = _tuples(raw)
        geoid = raw.get("telemetry", {}).get("msl_geoid") if isinstance(raw.get("telemetry"), dict) else None
        if isinstance(geoid, str) and not Path(geoid).is_absolute():  # relative to the config file
            raw["telemetry"] = {**raw["telemetry"], "msl_geoid": str(path.parent / geoid)}
        cfg = Config.model_validate(raw)
        cfg._path = str(path)
        if cfg.camera is not None:
            cfg.sensor()
    except ValidationError as exc:
        lines = [f"  {'.'.join(str(p) for p in e['loc']) or '(top level)'}: {e['msg']}" for e in exc.errors()]
        raise ConfigError(f"config file {str(path)!r} is invalid:\n" + "\n".join(lines)) from None
    except ValueError as exc:
        raise ConfigError(f"config file {str(path)!r} is invalid: {exc}") from None
    return cfg


def _tuples(v):
    """TOML arrays as tuples, through tables: strict validation takes tuples, and TOML has no other."""
    if isinstance(v, dict):
        return {k: _tuples(x) for k, x in v.items()}
    if isinstance(v, list):
        return tuple(_tuples(x) for x in v)
    return v


def write_calibration(path: str | Path, *, mount_misalignment_deg=None, boresight_misalignment_deg=None,
                      heading_bias_deg: float | None = None, time_offset_s: float | None = None,
                      budget: dict[str, dict[str, float | str]] | None = None, budget_note: str = "") -> None:
    """Write calibrated installation values into a config file, keeping its comments and layout
    (tomlkit); the file is validated before it is replaced. None leaves a value as it is.
    ``budget``: [accuracy.budget] entries to set ({source: {"normal": sigma, "kind": ...}}), each
    with ``budget_note`` as its comment ([accuracy.budget] made when the file has none)."""
    import tomlkit

    path = Path(path)
    doc = tomlkit.parse(path.read_text(encoding="utf-8"))
    if budget:
        if "accuracy" not in doc:
            doc["accuracy"] = tomlkit.table()
        if "budget" not in doc["accuracy"]:
            doc["accuracy"]["budget"] = tomlkit.table()
        table = doc["accuracy"]["budget"]
        for name, spec in budget.items():
            entry = tomlkit.inline_table()
            entry.update(spec)
            table[name] = entry
            if budget_note:
                table[name].comment(budget_note)
    updates = {("installation", "mount_misalignment_deg"): mount_misalignment_deg,
               ("installation", "boresight_misalignment_deg"): boresight_misalignment_deg,
               ("telemetry", "heading_bias_deg"): heading_bias_deg, ("telemetry", "time_offset_s"): time_offset_s}
    for (section, key), value in updates.items():
        if value is None:
            continue
        if section not in doc:
            doc[section] = tomlkit.table()
        doc[section][key] = [round(float(v), 6) for v in value] if np.ndim(value) else round(float(value), 6)
    text = tomlkit.dumps(doc)
    try:
        cfg = Config.model_validate(_tuples(tomllib.loads(text)))
        if cfg.camera is not None:
            cfg.sensor()
    except (ValidationError, ValueError) as exc:
        raise ConfigError(f"the calibrated config would not validate, {str(path)!r} left unchanged: {exc}") from None
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def copy_sections(dest: str | Path, source: str | Path, names: tuple[str, ...]) -> None:
    """The tables ``names`` of config ``source`` (those it has, with their comments: tomlkit) put
    into config ``dest`` in place of its own."""
    import tomlkit

    src = tomlkit.parse(Path(source).read_text(encoding="utf-8"))
    doc = tomlkit.parse(Path(dest).read_text(encoding="utf-8"))
    for name in names:
        if name in src:
            doc[name] = src[name]
    Path(dest).write_text(tomlkit.dumps(doc), encoding="utf-8")
