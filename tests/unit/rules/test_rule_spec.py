"""The stop rules as users name them: one table, eoloc.rules.spec.SPECS, read by every front end
(command line, config files, HTTP API, batch) -- and a row added to it reaches all of them.

The geometry oracle is the nadir: a camera looking straight down from (45 N, 7 E, 3000 m) sees
the point under it, so every rule's answer is (45, 7, 100 m) whatever stops the ray there (a
100 m height, a 2900 m range, a flat DEM at 100 m), independently of eoloc's kernels.
"""

from __future__ import annotations

import json
import subprocess
import sys

import httpx
import numpy as np
import pytest
import rasterio
from click.testing import CliRunner
from rasterio.transform import from_origin
from served import eoloc_serve

from eoloc.cli import main
from eoloc.errors import InputError
from eoloc.io.config import StopConfig, load_config
from eoloc.jobs.setup import accuracy_scenario
from eoloc.rules import AtHeight, AtRange, OnDEM, RangeFromRecords
from eoloc.rules.spec import FROM_RECORDS, SPECS, rule_from_values

NADIR = ["--lat", "45", "--lon", "7", "--aircraft-height", "3000", "--gimbal-angles", "0", "-90"]
POSE = {"lat_deg": 45.0, "lon_deg": 7.0, "h_m": 3000.0, "gimbal_deg": [0.0, -90.0]}
KEYS = {s.key for s in SPECS}


@pytest.fixture(scope="module")
def flat_dem(tmp_path_factory):
    """A DEM of ellipsoidal heights 100 m everywhere around the nadir point (written by rasterio)."""
    path = tmp_path_factory.mktemp("dem") / "flat.tif"
    with rasterio.open(path, "w", driver="GTiff", height=60, width=60, count=1, dtype="float32", crs="EPSG:4326",
                       transform=from_origin(6.97, 45.03, 0.001, 0.001)) as dst:
        dst.write(np.full((1, 60, 60), 100.0, np.float32))
    return path


def _at_nadir_100(got, what: str) -> None:
    """(lat, lon, h) is the point under the camera: 45, 7 to 1e-8 deg (1 mm), h 100 m to 1 cm."""
    np.testing.assert_allclose(got[:2], (45.0, 7.0), atol=1e-8, rtol=0, err_msg=what)
    assert abs(got[2] - 100.0) < 0.01, (what, got)


def _values(flat_dem) -> dict[str, tuple[list[str], object]]:
    """Each rule's command-line value and its value in a config file, all stopping at 100 m."""
    return {"range_m": (["--range", "2900"], 2900.0), "target_height_m": (["--target-height", "100"], 100.0),
            "dem": (["--dem", str(flat_dem), "--vertical", "ellipsoid"], [str(flat_dem)])}


def test_every_front_end_offers_exactly_the_rules_of_the_table():
    from eoloc.service.api import StopIn

    helps = {c: CliRunner().invoke(main, [c, "--help"]).output for c in ("locate", "track", "accuracy", "footprint")}
    for s in SPECS:
        assert all(s.flag in h for c, h in helps.items() if c != "footprint" or s.ground), s.flag
    assert "--range" not in helps["footprint"]  # a footprint stands on a surface: the ground rules only
    assert set(StopIn.model_fields) == KEYS
    assert set(StopConfig.model_fields) == KEYS | {"dem_vertical", "dem_crs"}
    assert {s.key for s in SPECS if s.ground} == {"target_height_m", "dem"}


def test_each_rule_stops_the_nadir_ray_at_100_m_from_the_cli_the_config_and_the_api(flat_dem, tmp_path):
    values = _values(flat_dem)
    assert set(values) == KEYS  # a rule added to the table needs a case here
    with eoloc_serve("--dem", f"flat={flat_dem}", "--vertical", "ellipsoid") as url:
        for key, (flags, config_value) in values.items():
            r = CliRunner().invoke(main, ["locate", *NADIR, *flags, "--json"])
            assert r.exit_code == 0, r.output
            cli = json.loads(r.output)
            api_value = "flat" if key == "dem" else config_value
            api = httpx.post(url + "/v1/locate", json={"pose": POSE, "stop": {key: api_value}}).json()["fixes"][0]
            cfg = tmp_path / f"{key}.toml"
            stop = (f'{key} = {json.dumps(config_value)}\ndem_vertical = "ellipsoid"\ndem_crs = "EPSG:4326"'
                    if key == "dem" else f"{key} = {config_value}")
            cfg.write_text('[camera]\nwidth = 640\nheight = 480\nhfov_deg = 30\n[gimbal]\nmodel = "az-el"\n'
                           "[accuracy]\npose = {lat_deg = 45, lon_deg = 7, h_m = 3000, gimbal_deg = [0, -90]}\n"
                           f"[accuracy.budget]\nyaw_deg = {{normal = 0.1}}\n[accuracy.stop]\n{stop}\n")
            scn = accuracy_scenario(load_config(cfg), cfg)
            f = scn.rule.locate(scn.sensor, scn.pose)
            for got in ((cli["lat"], cli["lon"], cli["h"]), (api["lat_deg"], api["lon_deg"], api["h_m"]),
                        (float(f.lat_deg), float(f.lon_deg), float(f.h_m))):
                _at_nadir_100(got, key)


def test_values_outside_a_rules_domain_are_refused_alike_everywhere(flat_dem, tmp_path):
    from pydantic import ValidationError

    from eoloc.service.api import StopIn

    r = CliRunner().invoke(main, ["locate", *NADIR, "--target-height", "-20000"])
    assert r.exit_code == 2 and "--target-height" in r.output and ">= -12000" in r.output
    with pytest.raises(InputError, match=r"target_height_m .* >= -12000"):
        rule_from_values({"target_height_m": -20000.0})
    for model in (StopIn, StopConfig):
        with pytest.raises(ValidationError, match="greater than or equal to -12000"):
            model(target_height_m=-20000.0)
        with pytest.raises(ValidationError, match="exactly one of range_m, target_height_m or dem"):
            model(range_m=5.0, target_height_m=1.0)
    r = CliRunner().invoke(main, ["locate", *NADIR, "--range", "10", "--target-height", "1"])
    assert r.exit_code == 2 and "choose one stop rule: --range R" in r.output
    cfg = tmp_path / "old.toml"
    cfg.write_text('[camera]\nwidth = 640\nheight = 480\nhfov_deg = 30\n[accuracy]\nstop = "range"\nrange_m = 1\n'
                   "[accuracy.budget]\nyaw_deg = {normal = 0.1}\n")
    with pytest.raises(Exception, match=r"\[accuracy.stop\] range_m = 10200"):  # the old shape, told how to write it
        load_config(cfg)


def test_rule_from_values_builds_the_rule_named_by_its_key():
    r = rule_from_values({"range_m": 5.0})
    assert isinstance(r, AtRange) and float(r.range_m) == 5.0
    assert isinstance(rule_from_values({"target_height_m": 1.0, "range_m": None}), AtHeight)
    assert isinstance(rule_from_values({"range_m": FROM_RECORDS}), RangeFromRecords)
    with pytest.raises(InputError, match="choose one stop rule: range_m"):
        rule_from_values({"range_m": None})
    with pytest.raises(InputError, match="no stop rule is named 'height_m'"):
        rule_from_values({"height_m": 1.0})
    with pytest.raises(InputError, match="needs a value"):
        SPECS[1].records_rule()  # a height has no per-target column
    with pytest.raises(TypeError, match=r"OnDEM needs an eoloc\.DEM"):
        rule_from_values({"dem": "a/path.tif"})  # Python passes a DEM object (the front ends open the files)
    assert {type(s.rule(1.0)).__name__ for s in SPECS if s.value != "dem"} == {"AtRange", "AtHeight"}
    assert OnDEM.__name__ in SPECS[2].build


NEW_RULE = """
import dataclasses, json, sys
import eoloc.rules.spec as S
S.SPECS = S.SPECS + (dataclasses.replace(S.SPECS[1], key="plane_height_m", flag="--plane-height", metavar="P",
                                         help="a test rule's height, metres"),)
from click.testing import CliRunner
from eoloc.cli import main
from eoloc.io.config import StopConfig
from eoloc.service.api import StopIn
r = CliRunner().invoke(main, ["locate", *sys.argv[1:], "--plane-height", "100", "--json"])
help = CliRunner().invoke(main, ["footprint", "--help"]).output
out = {"exit": r.exit_code, "fix": json.loads(r.output) if r.exit_code == 0 else r.output,
       "config": StopConfig(plane_height_m=100.0).plane_height_m, "api": StopIn(plane_height_m=100.0).plane_height_m,
       "rule": type(S.rule_from_values({"plane_height_m": 100.0})).__name__, "footprint_help": "--plane-height" in help}
try:
    StopIn(plane_height_m=1.0, range_m=2.0)
except Exception as exc:
    out["both"] = str(exc)
print(json.dumps(out))
"""


def test_a_row_added_to_the_table_reaches_every_front_end():
    """What adding a rule takes (docs/architecture.md "Everyday changes, counted"): its row in
    SPECS. Here a row naming an existing class under a new key, added before eoloc's front ends
    load: the command line, the config model and the API model all take it."""
    r = subprocess.run([sys.executable, "-c", NEW_RULE, *NADIR], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["exit"] == 0, out["fix"]
    _at_nadir_100((out["fix"]["lat"], out["fix"]["lon"], out["fix"]["h"]), "plane_height_m")
    assert out["config"] == out["api"] == 100.0 and out["rule"] == "AtHeight" and out["footprint_help"]
    assert "exactly one of range_m, target_height_m, dem or plane_height_m" in out["both"]


def test_the_single_target_path_takes_every_rule(flat_dem):
    """SensorModel.locate_one: the compiled kernel for a range or a height, the rule's own array
    path for the others (a DEM here): the nadir point either way."""
    from eoloc import AzElGimbal, Camera, SensorModel, open_dem

    sensor = SensorModel(Camera.from_hfov(30.0, 640, 480), AzElGimbal())
    dem = open_dem(flat_dem, vertical="ellipsoid")
    for rule in (AtRange(2900.0), AtHeight(100.0), OnDEM(dem)):
        lat, lon, h, rng, status = sensor.locate_one(45.0, 7.0, 3000.0, 0.0, 0.0, 0.0, 0.0, -90.0, rule=rule)
        assert status == 0, rule
        _at_nadir_100((lat, lon, h), type(rule).__name__)
        assert abs(rng - 2900.0) < 0.01
    assert AtRange(5.0).scalar_stop() is not None and OnDEM(dem).scalar_stop() is None
    assert AtHeight(np.array([1.0, 2.0])).scalar_stop() is None  # a value per target: the array path
    lat, *_, status = sensor.locate_one(45.0, 7.0, 3000.0, 0.0, 0.0, 0.0, 0.0, -90.0, 5000.0, 240.0, rule=OnDEM(dem))
    assert status == 7 and np.isnan(lat)  # OUT_OF_IMAGE, as the kernel path says it
