"""Checks written from the MISB standards and schemas, shared by tests of several packages: the
UAS Datalink key, ST 0601's 16-bit checksum restated from the standard (§6.5.3), the CoT Event
2.0 schema (MITRE's XSD, tests/data/conformance)."""

from __future__ import annotations

from where import TESTS

KEY = bytes.fromhex("060E2B34020B01010E01030101000000")


def bcc16(packet: bytes) -> int:
    """MISB ST 0601's checksum: the 16-bit sum of every byte up to the checksum value, each byte
    in the high half at even offsets and the low half at odd ones (ST 0601 §6.5.3)."""
    s = 0
    for i, b in enumerate(packet[:-2]):
        s += b << (8 * ((i + 1) % 2))
    return s & 0xFFFF


def cot_schema():
    """MITRE's CoT Event 2.0 schema (xmlschema)."""
    import xmlschema

    return xmlschema.XMLSchema(str(TESTS / "data" / "conformance" / "cot_event_2_0.xsd"))
