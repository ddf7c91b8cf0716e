"""eoloc.live.run, the live loop as a library: a source into a session into sinks, without the
command line. The reference for the targets is the batch path (`eoloc klv`'s job on the whole
file, its own reader and vectorised kernels); the source is the bundled mountain flight read as
a file, as `eoloc live FILE` reads it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import eoloc
from eoloc.jobs.klv import klv_job
from eoloc.live import BaseSink, LiveSession, NdjsonSink, run

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT = MOUNTAIN / "flight.klv"


class Collect(BaseSink):
    """A sink of the test: every update it is given, and what the loop told it."""

    name = "collect"

    def __init__(self) -> None:
        self.updates, self.ended, self.closed = [], [], False

    def send(self, updates) -> None:
        self.updates += updates

    def end(self, why) -> None:
        self.ended.append(why)

    def close(self) -> None:
        self.closed = True

    def summary(self) -> dict:
        return {"collected": len(self.updates)}


def test_a_file_through_the_loop_gives_the_batch_fixes_to_every_sink(tmp_path):
    collect, out = Collect(), tmp_path / "fixes.ndjson"
    source = str(FLIGHT)
    heard = []
    result = run(source, LiveSession(source), [collect, NdjsonSink(str(out))], report=lambda m, k: heard.append(k))
    assert result.why is None and result.fatal is None and collect.ended == [None] and collect.closed
    batch = klv_job(FLIGHT)
    assert result.summary["packets"] == len(batch.telemetry) == len(collect.updates)
    assert result.summary["collected"] == len(collect.updates) and result.summary["ndjson_lines"] > 0
    live = [f for u in collect.updates for f in u.fixes]
    ok = np.array([f["status"] == "OK" for f in live])
    assert ok.sum() == int(np.sum(batch.vmti.fixes.ok)) > 0
    got = np.array([[f["lat_deg"], f["lon_deg"], f["h_m"]] for f, good in zip(live, ok, strict=True) if good])
    want = np.stack([batch.vmti.fixes.lat_deg, batch.vmti.fixes.lon_deg, batch.vmti.fixes.h_m], -1)[
        np.asarray(batch.vmti.fixes.ok)]
    np.testing.assert_allclose(got[:, :2], want[:, :2], rtol=0, atol=1e-9)  # degrees: ~0.1 mm
    np.testing.assert_allclose(got[:, 2], want[:, 2], rtol=0, atol=1e-4)
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(lines) == result.summary["ndjson_lines"]
    targets = [f for f in lines if f["properties"]["what"] == "target" and f["geometry"] is not None]
    assert len(targets) == ok.sum()
    assert "start" in heard


def test_the_loop_stops_on_its_conditions_and_closes_every_sink():
    source = str(FLIGHT)
    first = Collect()
    r = run(source, LiveSession(source), [first], max_packets=5)
    assert r.why == "5 packets" and r.summary["packets"] == 5 and first.closed and first.ended == ["5 packets"]
    told = Collect()
    r = run(source, LiveSession(source), [told], should_stop=lambda: "asked" if len(told.updates) >= 3 else None)
    assert r.why == "asked" and len(told.updates) == 3

    class Broken(Collect):
        name = "broken"

        def send(self, updates) -> None:
            super().send(updates)
            if len(self.updates) >= 2:
                self.fatal = "the far end refused us"

    broken, other = Broken(), Collect()
    r = run(source, LiveSession(source), [broken, other])
    assert r.fatal == "the far end refused us" and r.why == "the broken output failed" and other.closed
    assert len(other.updates) == 2


def test_a_sink_that_raises_is_a_bug_the_loop_does_not_hide_but_the_others_are_closed():
    class Raises(Collect):
        def send(self, updates) -> None:
            raise RuntimeError("a bug in a sink")

    other = Collect()
    source = str(FLIGHT)
    with pytest.raises(RuntimeError, match="a bug in a sink"):
        run(source, LiveSession(source), [other, Raises()])
    assert other.closed
