"""`eoloc serve` as a user starts it, in its own process on a free loopback port."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
from ports import free_tcp_port

PROCESSES: dict[str, subprocess.Popen] = {}  # base URL -> the server's process, while it runs
LOGS: dict = {}  # base URL -> the file its output goes to


def rss_mb(url: str) -> float:
    """The resident memory of the server at ``url`` (MB, from /proc)."""
    status = Path(f"/proc/{PROCESSES[url].pid}/status").read_text()
    return int(next(x for x in status.splitlines() if x.startswith("VmRSS:")).split()[1]) / 1024


def stop_and_log(url: str) -> str:
    """Stop the server at ``url`` and return everything it printed."""
    proc = PROCESSES[url]
    proc.terminate()
    proc.wait(30)
    return _read(LOGS[url])


@contextlib.contextmanager
def eoloc_serve(*args: str):
    """Run `eoloc serve ARGS --port P` until the block ends; yields its base URL once /v1/health
    answers. Its output goes to a file (a pipe nobody reads would fill with the access log and stop
    the server after some 800 requests)."""
    port = free_tcp_port()
    log = tempfile.TemporaryFile()
    proc = subprocess.Popen([str(Path(sys.executable).parent / "eoloc"), "serve", *args, "--port", str(port)],
                            stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    LOGS[url] = log
    try:
        for _ in range(300):
            try:
                if httpx.get(url + "/v1/health", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                if proc.poll() is not None:
                    break
                time.sleep(0.1)
        else:
            proc.kill()
        if proc.poll() is not None:
            raise RuntimeError(f"eoloc serve {' '.join(args)} did not start:\n{_read(log)}")
        PROCESSES[url] = proc
        yield url
    finally:
        PROCESSES.pop(url, None)
        LOGS.pop(url, None)
        proc.terminate()
        proc.wait(30)
        log.close()


def _read(log) -> str:
    log.seek(0)
    return log.read().decode(errors="replace")
