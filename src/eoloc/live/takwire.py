"""How CoT events travel: TAK protocol version 0 (XML, eoloc's default and fallback) or
version 1 (protobuf), as ATAK's ``protocol.txt`` defines them.

- **Mesh** (UDP): each datagram ``0xbf 0x01 0xbf`` + one ``TakMessage``.
- **Stream** (TCP, TLS to a TAK server): every connection starts in XML. A server that speaks
  version 1 offers it (an event ``t-x-takp-v`` with ``<TakControl><TakProtocolSupport
  version="1"/>``, at most once per connection); the client asks (``t-x-takp-q``,
  ``<TakRequest version="1"/>``) and sends nothing else until the server answers
  (``t-x-takp-r``, ``<TakResponse status="true"/>``); from then on both sides send ``0xbf``
  + varint length + ``TakMessage``. A server that offers nothing, or refuses, stays on XML.

The XML → ``TakMessage`` conversion is the ``takproto`` package's (snstac, the library pytak
uses; the message definitions are TAK's own ``.proto`` files): ``<contact>``, ``<__group>``,
``<takv>``, ``<track>``, ``<status>``, ``<precisionlocation>`` become typed fields, every other
detail element (eoloc's ``<sensor>``, ``<link>``, ``<remarks>``, ``<__video>``) stays XML in
``xmlDetail``; times become milliseconds since 1970.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta

from ..io.cot import element_xml, event_xml

PROTOCOLS = ("xml", "1")  # --tak-protocol: 0 (XML) or 1 (protobuf)
MESH_HEADER = b"\xbf\x01\xbf"


def mesh(event: bytes) -> bytes:
    """One XML event as a TAK protocol v1 mesh datagram."""
    from takproto.constants import TAKProtoVer
    from takproto.functions import xml2proto

    return bytes(xml2proto(event, TAKProtoVer.MESH))


def stream(event: bytes) -> bytes:
    """One XML event as a TAK protocol v1 stream message (0xbf, varint length, TakMessage)."""
    from takproto.constants import TAKProtoVer
    from takproto.functions import xml2proto

    return bytes(xml2proto(event, TAKProtoVer.STREAM))


def request(uid: str, now: datetime | None = None) -> bytes:
    """The client's request for version 1 (``t-x-takp-q``)."""
    now = now or datetime.now(UTC)
    return event_xml(uid=uid, cot_type="t-x-takp-q", how="m-g", time=now, stale=now + timedelta(minutes=1),
                     lat=0.0, lon=0.0, hae=0.0,
                     detail=f"<TakControl>{element_xml('TakRequest', version='1')}</TakControl>")


class Negotiation:
    """The client side of a stream's negotiation, fed what the server sends while it is in XML.
    ``state``: "xml" (nothing offered yet, or refused), "asked" (request sent, waiting),
    "proto" (version 1 from now on: what the server sends after is protobuf, not read here).
    :meth:`feed` returns the bytes to send (the request) if any. Each event is parsed from its
    ``<event`` on, so no DTD (and no entity) ever reaches the parser."""

    def __init__(self, uid: str) -> None:
        self.uid, self.state, self.buffer, self.note = uid, "xml", b"", ""

    def feed(self, data: bytes) -> bytes:
        self.buffer += data
        out = b""
        while self.state != "proto" and (end := self.buffer.find(b"</event>")) >= 0:
            doc, self.buffer = self.buffer[:end + 8], self.buffer[end + 8:]
            start = doc.find(b"<event")
            try:
                ev = ET.fromstring(doc[start:]) if start >= 0 else None
            except ET.ParseError:
                continue
            kind = ev.get("type", "") if ev is not None else ""
            if kind == "t-x-takp-v" and self.state == "xml":
                versions = {e.get("version") for e in ev.iter("TakProtocolSupport")}
                if "1" in versions:
                    self.state = "asked"
                    out += request(self.uid)
                else:
                    self.note = f"the server offers TAK protocol {sorted(v for v in versions if v)}, not 1: XML kept"
            elif kind == "t-x-takp-r" and self.state == "asked":
                ok = any((e.get("status") or "").lower() == "true" for e in ev.iter("TakResponse"))
                self.state = "proto" if ok else "xml"
                self.note = "TAK protocol 1 (protobuf) agreed" if ok else "the server refused TAK protocol 1: XML kept"
        if self.state == "proto":
            self.buffer = b""
        elif len(self.buffer) > 1 << 20:  # a server that sends no </event>: keep memory bounded
            self.buffer = self.buffer[-65536:]
        return out
