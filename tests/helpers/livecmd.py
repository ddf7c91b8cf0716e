"""`eoloc live` as a user starts it, in its own process: a free UDP port to give it, its output up
to the line that says its socket is bound, and the packets it has written: each waited for, not
slept for."""

from __future__ import annotations

import json
import subprocess
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from eoloc.live.sources import DatagramSink


def until_listening(proc: subprocess.Popen) -> str:
    """What `eoloc live` printed up to its "listening on" line: its socket is bound from then on."""
    head = []
    while not head or "listening on" not in head[-1]:
        line = proc.stdout.readline()
        assert line or proc.poll() is None, "".join(head)
        head.append(line)
    return "".join(head)


def wait_for_packets(ndjson: Path, n: int, proc: subprocess.Popen, timeout_s: float = 120.0) -> int:
    """How many packets `eoloc live` has written to ``ndjson`` (it flushes per packet), waited for
    until there are ``n`` or the process ends (or, a safety net, ``timeout_s`` passes)."""
    deadline = time.monotonic() + timeout_s
    seen = 0
    while time.monotonic() < deadline and proc.poll() is None:
        if ndjson.exists():
            rows = [json.loads(x) for x in ndjson.read_text(encoding="utf-8").splitlines() if x.endswith("}")]
            seen = len({r["properties"]["packet"] for r in rows if r["properties"]["what"] == "aircraft"})
            if seen >= n:
                break
        time.sleep(0.05)
    return seen


def summary_of(log: str, stopped: str = "eoloc live stopped") -> dict:
    """The JSON summary `eoloc live` prints after its ``stopped`` line (``"eoloc live stopped
    (SIGINT)"`` to insist on why it stopped)."""
    return json.loads(log[log.index("{", log.index(stopped)):].splitlines()[0])


def wait_until(ready, what: str, timeout_s: float = 60.0) -> None:
    """Until ``ready()`` is true: waited for, however slow this machine is today; ``timeout_s`` only
    a safety net, after which the test fails naming ``what`` it waited for."""
    deadline = time.monotonic() + timeout_s
    while not ready():
        assert time.monotonic() < deadline, f"not after {timeout_s:.0f} s: {what}"
        time.sleep(0.02)


class CotReceiver(DatagramSink):
    """Every datagram on a UDP address (a multicast group joined) parsed as one CoT event."""

    def __init__(self, url: str) -> None:
        self.events: list[ET.Element] = []
        self.bad: list[bytes] = []
        super().__init__(url, self._parse)

    def wait_for(self, n: int, timeout_s: float = 60.0) -> None:
        """Until ``n`` datagrams have been read (the sender's count: on loopback none is lost, but
        the last ones may still wait in the socket's buffer when the sender has finished)."""
        wait_until(lambda: len(self.events) + len(self.bad) >= n, f"{n} CoT datagrams", timeout_s)

    def _parse(self, data: bytes, _arrival: float) -> None:
        try:
            ev = ET.fromstring(data)
            assert ev.tag == "event" and ev.find("point") is not None
            self.events.append(ev)
        except (ET.ParseError, AssertionError):
            self.bad.append(data)


def settle(path: Path, quiet_s: float = 1.5, timeout_s: float = 120.0) -> None:
    """Wait until ``path`` has stopped growing for ``quiet_s`` (the receiver has caught up)."""
    deadline, last, since = time.monotonic() + timeout_s, -1, time.monotonic()
    while time.monotonic() < deadline:
        size = path.stat().st_size if path.exists() else 0
        if size != last:
            last, since = size, time.monotonic()
        elif size and time.monotonic() - since > quiet_s:
            return
        time.sleep(0.1)
