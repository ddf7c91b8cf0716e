"""`eoloc serve` as a user starts it, in its own process on a free loopback port."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx

PROCESSES: dict[str, subprocess.Popen] = {}  # base URL -> the server's process, while it runs


def rss_mb(url: str) -> float:
    """The resident memory of the server at ``url`` (MB, from /proc)."""
    status = Path(f"/proc/{PROCESSES[url].pid}/status").read_text()
    return int(next(x for x in status.splitlines() if x.startswith("VmRSS:")).split()[1]) / 1024


def stop_and_log(url: str) -> str:
    """Stop the server at ``url`` and return everything it printed."""
    proc = PROCESSES[url]
    proc.terminate()
    out, _ = proc.communicate(timeout=30)
    return out.decode(errors="replace")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def eoloc_serve(*args: str):
    """Run `eoloc serve ARGS --port P` until the block ends; yields its base URL once /v1/health answers."""
    port = free_port()
    proc = subprocess.Popen([str(Path(sys.executable).parent / "eoloc"), "serve", *args, "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
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
            raise RuntimeError(f"eoloc serve {' '.join(args)} did not start:\n{proc.stdout.read().decode()}")
        PROCESSES[url] = proc
        yield url
    finally:
        PROCESSES.pop(url, None)
        proc.terminate()
        proc.wait(10)
