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


def _jpeg(width: int, height: int, *, make: str, model: str, focal_mm: float | None, f35_mm: float | None,
          gps: tuple[float, float, float] | None = None, picture=None) -> bytes:
    """A grey JPEG (or ``picture``, an (height, width, 3) uint8 array) with EXIF Make/Model, the
    focal lengths and (``gps``) latitude, longitude and altitude to 1e-6 arc-second and 1 mm."""
    from PIL.TiffImagePlugin import IFDRational

    im = Image.new("RGB", (width, height), (90, 90, 90)) if picture is None else Image.fromarray(picture, "RGB")
    exif = Image.Exif()
    exif[271], exif[272] = make, model
    sub = exif.get_ifd(0x8769)
    if focal_mm is not None:
        sub[37386] = focal_mm
    if f35_mm is not None:
        sub[41989] = int(f35_mm)
    if gps is not None:
        lat, lon, alt = gps
        g = exif.get_ifd(0x8825)
        g[1], g[2] = ("N" if lat >= 0 else "S"), _dms(lat)
        g[3], g[4] = ("E" if lon >= 0 else "W"), _dms(lon)
        g[5], g[6] = (1 if alt < 0 else 0), IFDRational(round(abs(alt) * 1000), 1000)
    buf = io.BytesIO()
    im.save(buf, "JPEG", exif=exif, quality=70)
    return buf.getvalue()


def _with_xmp(data: bytes, xmp: bytes) -> bytes:
    """The JPEG with an XMP segment right after SOI, where drones put theirs."""
    body = XMP_HEADER + xmp
    return data[:2] + b"\xff\xe1" + struct.pack(">H", len(body) + 2) + body + data[2:]


def write_photo(path: Path, width: int, height: int, tags: dict | None, *, make: str = "DJI", model: str = "FC330",
                focal_mm: float | None = None, f35_mm: float | None = None, picture=None) -> Path:
    """A grey JPEG of width x height (or ``picture``) with EXIF (make, model, focal length) and,
    unless ``tags`` is None, the drone-dji XMP ``tags``."""
    data = _jpeg(width, height, make=make, model=model, focal_mm=focal_mm, f35_mm=f35_mm, picture=picture)
    path.write_bytes(data if tags is None else _with_xmp(data, xmp_packet(tags)))
    return path


# -- every vendor ------------------------------------------------------------------------------------

VENDOR_NS = {"dji": ("drone-dji", "http://www.dji.com/drone-dji/1.0/"),
             "skydio": ("drone-skydio", "https://www.skydio.com/drone-skydio/1.0/"),
             "parrot": ("drone-parrot", "http://www.parrot.com/drone-parrot/1.0/"),
             "pix4d": ("Camera", "http://pix4d.com/camera/1.0"),
             "exif": ("exif", "http://ns.adobe.com/exif/1.0/")}


def xmp_document(vendor: str, tags: dict, *, struct_as_description: bool = False) -> bytes:
    """An XMP packet with ``tags`` in the vendor's namespace: plain values as attributes of the
    rdf:Description, dict values as structs (elements with rdf:parseType="Resource", or a nested
    rdf:Description when ``struct_as_description``)."""
    prefix, uri = VENDOR_NS[vendor]
    plain = {k: v for k, v in tags.items() if not isinstance(v, dict)}
    attrs = "\n   ".join(f"{prefix}:{k}={quoteattr(str(v))}" for k, v in plain.items())
    inner = []
    for name, fields in tags.items():
        if not isinstance(fields, dict):
            continue
        if struct_as_description:
            body = " ".join(f"{prefix}:{k}={quoteattr(str(v))}" for k, v in fields.items())
            inner.append(f"   <{prefix}:{name}>\n    <rdf:Description {body}/>\n   </{prefix}:{name}>")
        else:
            body = "".join(f"<{prefix}:{k}>{v}</{prefix}:{k}>" for k, v in fields.items())
            inner.append(f'   <{prefix}:{name} rdf:parseType="Resource">{body}</{prefix}:{name}>')
    xml = (f'<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>\n'
           f'<x:xmpmeta xmlns:x="adobe:ns:meta/">\n <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
           f'  <rdf:Description rdf:about="" xmlns:{prefix}="{uri}"\n   {attrs}>\n' + "\n".join(inner) +
           '\n  </rdf:Description>\n </rdf:RDF>\n</x:xmpmeta>\n<?xpacket end="w"?>')
    return xml.encode("utf-8")


def _dms(x: float):
    from PIL.TiffImagePlugin import IFDRational

    x = abs(x)
    d = int(x)
    m = int((x - d) * 60)
    s = round(((x - d) * 60 - m) * 60 * 1e6)
    return (IFDRational(d, 1), IFDRational(m, 1), IFDRational(s, 1_000_000))


def write_vendor_photo(path: Path, width: int, height: int, vendor: str, tags: dict, *, make: str, model: str,
                       gps: tuple[float, float, float] | None = None, focal_mm: float | None = None,
                       f35_mm: float | None = None, struct_as_description: bool = False) -> Path:
    """A grey JPEG with EXIF Make/Model (+ GPS latitude, longitude, altitude to 1e-6 arc-second and
    1 mm when ``gps`` is given) and the vendor's XMP ``tags``."""
    data = _jpeg(width, height, make=make, model=model, focal_mm=focal_mm, f35_mm=f35_mm, gps=gps)
    path.write_bytes(_with_xmp(data, xmp_document(vendor, tags, struct_as_description=struct_as_description)))
    return path


def gps_as_written(lat: float, lon: float, alt: float) -> tuple[float, float, float]:
    """What ``write_vendor_photo`` stores: the EXIF rationals' values."""
    def back(x):
        d, m, s = (float(r) for r in _dms(x))
        return (d + m / 60 + s / 3600) * (1 if x >= 0 else -1)

    return back(lat), back(lon), round(abs(alt) * 1000) / 1000 * (1 if alt >= 0 else -1)
