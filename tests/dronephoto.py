"""Synthetic drone photos for the tests: a JPEG with the XMP and EXIF tags a drone writes.

The XMP packet is written as a drone writes it (an APP1 segment "http://ns.adobe.com/xap/1.0/"
with an rdf:Description whose attributes are the vendor's tags); EXIF Make/Model/FocalLength
through Pillow. Nothing here comes from eoloc.
"""

from __future__ import annotations

import io
import struct
from pathlib import Path
from xml.sax.saxutils import quoteattr

from PIL import Image

XMP_HEADER = b"http://ns.adobe.com/xap/1.0/\x00"


def xmp_packet(tags: dict, ns: tuple[str, str] = ("drone-dji", "http://www.dji.com/drone-dji/1.0/")) -> bytes:
    prefix, uri = ns
    attrs = "\n   ".join(f"{prefix}:{k}={quoteattr(str(v))}" for k, v in tags.items())
    xml = (f'<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>\n'
           f'<x:xmpmeta xmlns:x="adobe:ns:meta/">\n <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
           f'  <rdf:Description rdf:about="DJI Meta Data" xmlns:tiff="http://ns.adobe.com/tiff/1.0/"\n'
           f'   xmlns:{prefix}="{uri}"\n   {attrs}>\n  </rdf:Description>\n </rdf:RDF>\n</x:xmpmeta>\n'
           f'<?xpacket end="w"?>')
    return xml.encode("utf-8")


def write_photo(path: Path, width: int, height: int, tags: dict | None, *, make: str = "DJI", model: str = "FC330",
                focal_mm: float | None = None, f35_mm: float | None = None) -> Path:
    """A grey JPEG of width x height with EXIF (make, model, focal length) and, unless ``tags`` is
    None, the drone-dji XMP ``tags``."""
    im = Image.new("RGB", (width, height), (90, 90, 90))
    exif = Image.Exif()
    exif[271], exif[272] = make, model
    sub = exif.get_ifd(0x8769)
    if focal_mm is not None:
        sub[37386] = focal_mm
    if f35_mm is not None:
        sub[41989] = int(f35_mm)
    buf = io.BytesIO()
    im.save(buf, "JPEG", exif=exif, quality=70)
    data = buf.getvalue()
    if tags is not None:  # the XMP segment right after SOI, where drones put theirs
        body = XMP_HEADER + xmp_packet(tags)
        seg = b"\xff\xe1" + struct.pack(">H", len(body) + 2) + body
        data = data[:2] + seg + data[2:]
    path.write_bytes(data)
    return path
