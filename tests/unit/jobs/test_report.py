"""`eoloc report`: the flight-test accuracy report on calibration flights, rendered in headless
Chromium (every picture loads, nothing is fetched, no console error), its CSV, and the held-out
calibration against a platform whose installation error is known."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest
from browser import page_state
from click.testing import CliRunner

import eoloc
from eoloc.cli import main

DEMO = Path(eoloc.__file__).parent / "data" / "demo"


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    r = CliRunner().invoke(main, ["compensate", "simulate", "--config", str(DEMO / "camera.toml"), "--flights", "3",
                                  "--test-flights", "0", "--looks", "80", "--out", str(d / "cal")])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["report", str(d / "cal" / "train.csv"), "--config", str(DEMO / "camera.toml"),
                                  "--dem", str(d / "cal" / "dem.tif"), "--vertical", "ellipsoid", "--compensation",
                                  "--bootstrap", "300", "--out", str(d / "out")])
    assert r.exit_code == 0, r.output
    return d / "out", r.output


def test_report_renders_in_chromium_with_every_plot(report):
    out, _ = report
    html = (out / "report.html").read_text(encoding="utf-8")
    assert not re.search(r'<(script|link|img)[^>]+(src|href)="(https?:|//)', html)  # nothing fetched
    names = re.findall(r'data-figure="([^"]+)"', html)
    assert names == ["located-errors", "located-factors", "located-coverage", "stage1-errors", "stage2-errors",
                     "compensation"]
    state, errors = page_state(
        out / "report.html",
        "const imgs = [...document.images];"
        "return {n: imgs.length, loaded: imgs.filter(i => i.complete && i.naturalWidth > 300).length,"
        " declared: +document.body.dataset.figures, tables: document.querySelectorAll('table').length,"
        " h1: document.querySelector('h1').textContent};")
    assert errors == []
    assert state["n"] == state["loaded"] == state["declared"] == len(names)
    assert state["tables"] >= 8 and state["h1"] == "eoloc accuracy report: train.csv"


def test_report_csv_holds_every_observation_and_stage(report):
    out, text = report
    with (out / "report_points.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 240
    for key in ("located_horizontal_m", "calibrated_horizontal_m", "held_out_horizontal_m", "range_m", "oblique_deg"):
        assert key in rows[0]
    with (out / "report_summary.csv").open(newline="") as fh:
        summary = list(csv.DictReader(fh))
    stages = {r["stage"] for r in summary}
    assert stages == {"as located", "calibrated (in sample)", "calibrated (flight held out)"}
    overall = next(r for r in summary if r["stage"] == "as located" and r["group"] == "all")
    located = np.array([float(r["located_horizontal_m"]) for r in rows if r["located_horizontal_m"]])
    assert float(overall["cep50_m"]) == pytest.approx(np.median(located), abs=1e-3)
    assert "flight held out" in text
    # progress off a terminal: each step said as it starts
    for step in ("locating...", "calibrating with each flight held out...", "cross-validating the compensation..."):
        assert step in text, step


def test_held_out_calibration_recovers_a_mount_error(tmp_path):
    """Observations whose only error is a known mount misalignment: located with the nominal sensor
    they are off by tens of metres; calibrated with each flight held out, by centimetres."""
    import dataclasses

    from eoloc.accuracy.calflight import FlightNoise, InstallationErrors, calibration_flights
    from eoloc.io.config import load_config
    from eoloc.io.records import Records
    from eoloc.io.writers import write_layer
    from eoloc.jobs.report import report_job

    cfg = load_config(DEMO / "camera.toml")
    sensor = cfg.sensor()
    quiet = FlightNoise(**{f.name: 0.0 for f in dataclasses.fields(FlightNoise)})
    mount_only = InstallationErrors(gimbal_bias_deg=(0.0, 0.0), mount_misalignment_deg=(0.15, -0.1, 0.08),
                                    boresight_misalignment_deg=(0.0, 0.0, 0.0), heading_bias_deg=0.0,
                                    time_offset_s=0.0, dem_bias_m=0.0)
    flights = calibration_flights(sensor, n_flights=3, looks_per_flight=60, seed=4, errors=mount_only,
                                  noise=quiet)
    (obs,) = write_layer(tmp_path, "obs", Records(dict(flights.columns)), ["csv"])
    job = report_job(cfg, DEMO / "camera.toml", obs, estimate=("mount",), n_boot=0)
    located, _, held = (s.evaluation.overall.value for s in job.stages)
    assert located["cep50_m"] > 5.0
    assert held["ce90_m"] < 0.05
