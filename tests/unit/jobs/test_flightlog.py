"""A drone video's telemetry joined with the flight log of the same flight
(eoloc.jobs.flightlog): the time offset found against the log's own recording edge, and each
record's pose taken from the log at the video's time + that offset — checked against pandas'
reading of the log (issue 55: the job's own test)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from where import DATA

from eoloc.io.sources import read_source

FOLSOM_SRT = DATA / "drone" / "srt" / "MICK_folsomake_DJI_0031-01.srt"
FOLSOM_LOG = DATA / "drone" / "logs" / "Dec-22nd-2023-11-56AM-Flight-Airdata.csv"


def test_48_real_srt_synced_with_its_flight_log():
    """The real DJI Mini 2 SE clip (no attitude, positions to 1e-4°, H above take-off) and the
    Airdata log of its flight: the offset found puts every SRT height within 0.15 m of the log's
    (pandas, read by hand from the CSV) and every position within 12 m (the SRT's rounding); it is
    within a second after an isVideo rising edge (the recording's start); each record's attitude
    is the log's gimbal angles there."""
    from eoloc.jobs.flightlog import WithFlightLog
    from eoloc.jobs.inputs import read_inputs

    inputs = read_inputs(WithFlightLog(str(FOLSOM_SRT), str(FOLSOM_LOG)))
    note = next(i.message for i in inputs.issues if "poses from the flight log" in i.message)
    offset = float(note.split("time + ")[1].split(" s")[0])
    log = pd.read_csv(FOLSOM_LOG, skipinitialspace=True)
    log.columns = [c.strip() for c in log.columns]
    t_log = log["time(millisecond)"].to_numpy() / 1000.0
    edges = t_log[np.flatnonzero(np.diff(log["isVideo"].to_numpy()) == 1) + 1]
    assert ((offset - edges >= 0) & (offset - edges <= 1.0)).any(), (offset, edges)
    srt_rows = read_source(FOLSOM_SRT).telemetry.columns
    t = srt_rows["time_s"] + offset
    h_log = np.interp(t, t_log, log["height_above_takeoff(feet)"].to_numpy() * 0.3048)
    assert np.abs(h_log - srt_rows["h_rel_m"]).max() < 0.15
    lat = np.interp(t, t_log, log["latitude"].to_numpy())
    lon = np.interp(t, t_log, log["longitude"].to_numpy())
    apart = np.hypot((lat - srt_rows["lat_deg"]) * 111_320, (lon - srt_rows["lon_deg"]) * 111_320 * np.cos(0.676))
    assert apart.max() < 12.0, apart.max()
    c = inputs.telemetry.columns
    np.testing.assert_allclose(c["pitch_deg"], np.interp(t, t_log, log["gimbal_pitch(degrees)"]), atol=0.05)
    assert np.isfinite(c["yaw_deg"]).all() and np.isfinite(c["h_m"]).all()
    # what the SRT alone lacked (attitude, a placeable height) the log answered: no longer reported
    assert not [i for i in inputs.issues if "no camera attitude" in i.message or "placed in height" in i.message]
