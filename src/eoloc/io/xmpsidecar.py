"""XMP sidecars: a drone photo's refined pose written back in its own XMP packet (its vendor's tags
and namespaces as the photo has them), for `exiftool -tagsfromfile NAME.xmp -xmp:all NAME.JPG` or
any tool that reads a sidecar beside the photo.

The packet is the photo's own, parsed (defusedxml) and written again with only the pose's values
changed: the camera attitude in the tags :func:`eoloc.io.photo.read_photo` read it from (DJI and
Autel ``drone-dji:Gimbal*Degree``, Skydio ``drone-skydio:CameraOrientationNED``, Parrot
``drone-parrot:Camera*Degree``, older Autel ``Camera:Yaw/Pitch/Roll`` with its pitch 0 at nadir,
Teal ``exif:Camera*`` on top of its platform angles) and, when refinement moved the position, the
XMP position tags by the same change (DJI/Autel ``GpsLatitude``, ``GpsLongitude``,
``AbsoluteAltitude``; Skydio ``Latitude``, ``Longitude``, ``AbsoluteAltitude``): each height in the
datum the photo writes it in, since only the difference is added. A position that lives in the
photo's EXIF (Parrot, older Autel, Teal) is not in its XMP: the sidecar leaves it, and says so.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

#: per vendor (the key :func:`eoloc.io.photo.parse_xmp` files it under): the attitude's tags (yaw,
#: pitch, roll), the struct that holds them (or None), the tag's pitch minus eoloc's, and the
#: position's tags (latitude, longitude, height) when the XMP carries it
ATTITUDE_TAGS = {
    "dji": (("GimbalYawDegree", "GimbalPitchDegree", "GimbalRollDegree"), None, 0.0,
            ("GpsLatitude", "GpsLongitude", "AbsoluteAltitude")),
    "skydio": (("Yaw", "Pitch", "Roll"), "CameraOrientationNED", 0.0, ("Latitude", "Longitude", "AbsoluteAltitude")),
    "parrot": (("CameraYawDegree", "CameraPitchDegree", "CameraRollDegree"), None, 0.0, None),
    "pix4d": (("Yaw", "Pitch", "Roll"), None, 90.0, None),
    "exif": (("CameraYaw", "CameraPitch", "CameraRoll"), None, 0.0, None),  # Teal: + Platform*
}


def refined_sidecar(photo_path: str | Path, yaw_deg: float, pitch_deg: float, roll_deg: float,
                    shift: tuple[float, float, float] | None = None) -> tuple[str, list[str]]:
    """The XMP sidecar (text) of ``photo_path`` with the camera's refined attitude (eoloc's yaw,
    pitch, roll, degrees) and, given ``shift`` (the refined minus the given latitude, longitude
    (deg) and height (m)), the position tags moved by it; and notes on what it could not write."""
    from xml.etree import ElementTree as ET

    from defusedxml.ElementTree import fromstring, iterparse
    from PIL import Image

    from .photo import NAMESPACES, PhotoError, raw_xmp, xmpmeta_text

    with Image.open(photo_path) as im:
        raw = raw_xmp(im)
    text = xmpmeta_text(raw) if raw else ""
    if not text.startswith("<x:xmpmeta"):
        raise PhotoError(f"{photo_path}: no XMP packet (x:xmpmeta) to write a sidecar of")
    prefixes = {uri: prefix for _, (prefix, uri) in iterparse(io.StringIO(text), events=("start-ns",))}
    root = fromstring(text)

    def local(tag: str) -> tuple[str, str]:
        uri, _, name = tag[1:].partition("}") if tag.startswith("{") else ("", "", tag)
        return uri, name

    def vendor_of(uri: str) -> str | None:  # rdf's own elements are the packet's frame, not values
        return next((k for k, frag in NAMESPACES.items() if frag in uri and k != "rdf"), None)

    # where each vendor's values are: {vendor: {name: (element, attribute key, or None: its text)}},
    # a struct's fields as "Struct.Field" (parse_xmp's names)
    found: dict[str, dict[str, tuple]] = {}

    def walk(el, prefix: str = "") -> None:
        v = vendor_of(local(el.tag)[0])
        own = [k for k in el.attrib if vendor_of(local(k)[0]) is not None]
        inner = f"{prefix}{local(el.tag)[1]}." if v is not None and (len(el) or own) else prefix
        for k in own:
            found.setdefault(vendor_of(local(k)[0]), {}).setdefault(inner + local(k)[1], (el, k))
        if v is not None and len(el) == 0 and not own:
            found.setdefault(v, {}).setdefault(prefix + local(el.tag)[1], (el, None))
        for child in el:
            walk(child, inner)

    walk(root)
    vendor = next((v for v in ("dji", "skydio", "parrot", "pix4d") if v in found), None)
    if vendor is None and {"CameraYaw", "PlatformYaw"} & set(found.get("exif", {})):
        vendor = "exif"
    if vendor is None:
        raise PhotoError(f"{photo_path}: its XMP holds no drone attitude tags to write the refined one into")
    names, struct, pitch_offset, position = ATTITUDE_TAGS[vendor]
    tags = found[vendor]

    def key(name: str) -> str:
        return f"{struct}.{name}" if struct else name

    def get(tag: str) -> float:
        el, attr = tags[tag]
        return _number(el.text if attr is None else el.attrib[attr])

    def put(tag: str, value: float, digits: int) -> None:
        el, attr = tags[tag]
        if attr is None:
            el.text = f"{value:+.{digits}f}"
        else:
            el.attrib[attr] = f"{value:+.{digits}f}"

    values = [yaw_deg, pitch_deg + pitch_offset, roll_deg]
    if vendor == "exif":  # Teal: the camera's angles on top of the platform's
        values = [v - (get(f"Platform{axis}") if f"Platform{axis}" in tags else 0.0)
                  for v, axis in zip(values, ("Yaw", "Pitch", "Roll"), strict=True)]
        values[0] = (values[0] + 180.0) % 360.0 - 180.0
    notes = []
    for name, value in zip(names, values, strict=True):
        if key(name) in tags:
            put(key(name), value, 6)
        elif name != names[2]:
            raise PhotoError(f"{photo_path}: its XMP has no {name} to write the refined attitude into")
        elif abs(value) > 1e-9:
            notes.append(f"{photo_path}: its XMP has no {name}: the refined roll ({value:+.6f} deg) is not in the "
                         "sidecar (photos_refined.csv has it)")
    if shift is not None and any(abs(s) > 0 for s in shift):
        if position is None or not all(n in tags for n in position):
            notes.append(f"{photo_path}: its position is in its EXIF, not its XMP: the refined position is in "
                         "photos_refined.csv and geo.txt, not in the sidecar")
        else:
            for name, delta, digits in zip(position, shift, (10, 10, 4), strict=True):
                put(name, get(name) + delta, digits)
    for uri, prefix in prefixes.items():
        if prefix and not (prefix.startswith("ns") and prefix[2:].isdigit()):
            ET.register_namespace(prefix, uri)
    body = ET.tostring(root, encoding="unicode")
    return ('<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>\n' + body + '\n<?xpacket end="w"?>\n', notes)


def _number(text: str | None) -> float:
    """A tag's number ("+12.5", or a rational "25/2")."""
    s = (text or "").strip()
    if "/" in s:
        a, b = s.split("/", 1)
        return float(a) / float(b)
    value = float(s)
    if not math.isfinite(value):
        raise ValueError(s)
    return value
