"""A free port on loopback for a server the tests start in another process (eoloc, a TAK server,
an RTSP server), which must bind it itself. Where a test serves in its own process it binds
port 0 and keeps that socket instead (no gap between asking and binding)."""

from __future__ import annotations

import socket


def _free(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_udp_port() -> int:
    return _free(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    return _free(socket.SOCK_STREAM)
