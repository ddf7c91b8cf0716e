"""Drone photos: the camera's pose and intrinsics from a JPEG's EXIF and XMP.

Read with Pillow (already here for matplotlib; its ``getexif`` and ``getxmp``) and defusedxml
(which Pillow uses for XMP: an XML parser hardened against entity expansion, since a photo's XMP
is input like any other). What each vendor writes, and the rules taken from it, with their
source:

**DJI** (``drone-dji:`` namespace; DJI's own "Mavic 3 Enterprise Image Processing Guide" lists the
tags; the datum rule is the one OpenAthena settled on after its issue #65):

- position: ``GpsLatitude`` / ``GpsLongitude`` (else EXIF GPS); height ``AbsoluteAltitude``: the
  EGM96 geoid's (MSL) for XMP ``Version`` < 1.5 without RTK, the WGS-84 ellipsoid's otherwise
  (``RtkFlag`` > 0 or ``GpsStatus`` RTK: ellipsoidal); ``RelativeAltitude`` is above the take-off
  point, reported beside it, never used as a height;
- attitude: ``GimbalYawDegree`` / ``GimbalPitchDegree`` / ``GimbalRollDegree`` are the camera's own
  attitude in the local level frame (yaw from true north, pitch negative below the horizon), not
  angles relative to the aircraft: eoloc takes them as the pose's yaw/pitch/roll with a zero
  az-el gimbal (``Flight*Degree`` is the aircraft's, shown only). All three exactly 0 (DJI Mini 2
  and others write that when the gimbal angle is unknown) or missing: refused, named;
- intrinsics: ``CalibratedFocalLength`` and ``CalibratedOpticalCenterX/Y`` (pixels, enterprise
  models) when present; else the camera database (:mod:`eoloc.sensor.dronemodels`: make + model,
  visible or thermal from ``ImageSource``, scaled to the image's size); else EXIF
  ``FocalLengthIn35mmFilm`` with a warning;
- laser range finder (H20 series, M30, M3T): ``LRFTargetDistance`` (m, along the optical axis,
  ``LRFStatus`` Normal) — the centre is then located by range — and DJI's own answer
  ``LRFTargetLat/Lon/AbsAlt`` (the last in ``AbsoluteAltitude``'s datum), shown beside eoloc's.

**Skydio** (``drone-skydio:``): ``Latitude``/``Longitude`` (else EXIF GPS); height ``AbsoluteAltitude``
  above the EGM96 geoid (OpenAthena's reading of Skydio 2/X2 files), else EXIF ``GPSAltitude``,
  ellipsoidal (Skydio's X10 metadata overview); attitude ``CameraOrientationNED`` ``Yaw``/``Pitch``/
  ``Roll`` (the camera's, earth-referenced; pitch negative below the horizon); intrinsics
  ``CalibratedFocalLengthX/Y`` and ``CalibratedOpticalCenterX/Y`` (pixels; Skydio's "camera and
  metadata overview").

**Parrot** (``drone-parrot:``, Parrot's "photo metadata" reference): position and height from EXIF
GPS; the height is above the EGM96 geoid on ANAFI 4K/Thermal/USA and above the WGS-84 ellipsoid on
ANAFI Ai; attitude ``CameraYawDegree``/``CameraPitchDegree``/``CameraRollDegree``.

**Autel**: newer firmware writes DJI's ``drone-dji:`` tags (read as DJI's, but its
``AbsoluteAltitude`` taken as ellipsoidal, as OpenAthena does); older firmware Pix4D's ``Camera:``
tags: ``Yaw``, ``Pitch`` (0 at nadir, 90 at the horizon: eoloc's pitch is ``Pitch`` - 90),
``Roll``, with the position and an EGM96 height from EXIF GPS (that firmware says ellipsoidal and
is not; OpenAthena's finding).

**Teal** (Teledyne FLIR): EXIF GPS (height above EGM96); the camera's attitude is the platform's
plus the camera's relative angles, ``exif:PlatformYaw`` + ``exif:CameraYaw`` (and Pitch, Roll;
rationals), as OpenAthena sums them.

The XMP is parsed with its namespaces (defusedxml), so one vendor's tag is never taken for
another's. A calibration in the file is used when it fits the image: scaled when the image was
resized (its principal point gives the size it was made for), refused when it belongs to another
camera (a Skydio IR frame carries the visible camera's calibration: another aspect ratio); then the
camera database; then EXIF 35 mm equivalent with a note.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError


class PhotoError(InputError):
    """A photo eoloc cannot take: the message names the file, the tag and the fix."""


@dataclass(frozen=True)
class PhotoPose:
    """What a photo says. Angles in degrees, heights ellipsoidal (m); the camera's attitude as
    yaw (optical axis' azimuth clockwise from true north), pitch (its elevation, negative below the
    horizon) and roll (the image's about the axis)."""

    path: str
    vendor: str
    make: str
    model: str
    width: int
    height: int
    lat_deg: float
    lon_deg: float
    h_m: float
    height_rule: str  # how h_m was read (the tag and its datum)
    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    camera: object  # eoloc Camera
    camera_source: str
    thermal: bool = False
    relative_altitude_m: float | None = None
    lrf_range_m: float | None = None
    lrf_target: tuple[float, float, float] | None = None  # the vendor's own (lat, lon, h ellipsoidal)
    time: str | None = None
    notes: list[str] = field(default_factory=list)


def _num(xmp: dict, key: str, path: str, *, required: bool = True) -> float | None:
    """A tag's number (a rational "a/b" too); None (or a PhotoError naming it, when required) if absent."""
    raw = xmp.get(key)
    if raw is None or (isinstance(raw, str) and not raw.strip()):
        if required:
            raise PhotoError(f"{path}: the XMP has no {key}: eoloc cannot place the camera without it (a photo "
                             "re-saved by an editor may have lost its drone tags: use the original file)")
        return None
    try:
        text = str(raw).strip()
        num, _, den = text.partition("/")
        v = float(num) / float(den) if den else float(text)
    except (ValueError, ZeroDivisionError):
        raise PhotoError(f"{path}: XMP {key} = {raw!r} is not a number") from None
    if not math.isfinite(v):
        raise PhotoError(f"{path}: XMP {key} = {raw!r} is not a finite number")
    return v


#: The vendors' XMP namespaces, by a part of their URI (http or https, with or without the slash).
NAMESPACES = {"dji": "dji.com/drone-dji", "skydio": "skydio.com/drone-skydio", "parrot": "parrot.com/drone-parrot",
              "pix4d": "pix4d.com/camera", "exif": "ns.adobe.com/exif/1.0", "tiff": "ns.adobe.com/tiff/1.0",
              "rdf": "www.w3.org/1999/02/22-rdf-syntax-ns"}


def raw_xmp(im) -> bytes | str | None:
    """The XMP packet of an open Pillow image (a JPEG's APP1 segment, a TIFF's tag 700), or None."""
    return im.info.get("xmp") or (im.tag_v2.get(700) if hasattr(im, "tag_v2") else None)


def xmpmeta_text(raw: bytes | str) -> str:
    """The x:xmpmeta element's text of an XMP packet (the xpacket wrapper and padding left out)."""
    text = raw.decode("utf-8", "replace") if isinstance(raw, bytes) else raw
    text = text[text.find("<x:xmpmeta"):] if "<x:xmpmeta" in text else text
    end = text.rfind("</x:xmpmeta>")
    text = text[:end + len("</x:xmpmeta>")] if end >= 0 else text
    return text.strip().lstrip("\ufeff")


def parse_xmp(raw: bytes | str | None) -> dict[str, dict[str, str]]:
    """An XMP packet's values by vendor (the keys of :data:`NAMESPACES`; "other" for the rest):
    {vendor: {name: text}}, from the rdf:Description attributes and leaf elements; a struct's fields
    as "Struct.Field", a list's items joined by commas. Parsed with defusedxml (no entity expansion)."""
    from defusedxml.ElementTree import ParseError, fromstring

    out: dict[str, dict[str, str]] = {}
    if not raw:
        return out
    try:
        root = fromstring(xmpmeta_text(raw))
    except (ParseError, ValueError) as exc:
        raise PhotoError(f"the XMP packet is not valid XML ({exc})") from None

    def vendor(tag: str) -> tuple[str, str]:
        uri, _, local = tag[1:].partition("}") if tag.startswith("{") else ("", "", tag)
        return next((k for k, frag in NAMESPACES.items() if frag in uri), "other"), local

    def put(tag: str, value: str, prefix: str = "") -> None:
        v, local = vendor(tag)
        out.setdefault(v, {}).setdefault(prefix + local, value)

    def walk(el, prefix: str = "") -> None:
        for k, val in el.attrib.items():
            if vendor(k)[0] != "rdf":
                put(k, val, prefix)
        for child in el:
            v, local = vendor(child.tag)
            if v == "rdf" and local in ("Description", "li"):
                walk(child, prefix)
            elif v == "rdf" and local in ("Seq", "Bag", "Alt"):
                continue
            elif len(child) == 0 and not any(vendor(k)[0] != "rdf" for k in child.attrib):
                put(child.tag, (child.text or "").strip(), prefix)
            else:
                items = [li for li in child.iter() if vendor(li.tag) == ("rdf", "li")]
                if items and all(len(li) == 0 for li in items):
                    put(child.tag, ",".join((li.text or "").strip() for li in items), prefix)
                else:
                    walk(child, f"{prefix}{local}.")

    for desc in root.iter():
        if vendor(desc.tag) == ("rdf", "Description"):
            walk(desc)
    return out


def _exif_gps(exif) -> tuple[float | None, float | None]:
    lat, lon, _ = _exif_gps_3d(exif)
    return lat, lon


def _exif_gps_3d(exif) -> tuple[float | None, float | None, float | None]:
    """EXIF GPS latitude, longitude (degrees) and GPSAltitude (m; negative when GPSAltitudeRef is 1)."""
    try:
        gps = exif.get_ifd(0x8825)
    except Exception:
        return None, None, None

    def deg(values, ref, neg):
        if not values or len(values) != 3:
            return None
        d, m, s = (float(x) for x in values)
        v = d + m / 60.0 + s / 3600.0
        return -v if ref in neg else v

    alt = gps.get(6)
    try:
        alt = None if alt is None else float(alt) * (-1.0 if gps.get(5) in (1, b"\x01") else 1.0)
    except (TypeError, ValueError, ZeroDivisionError):
        alt = None
    return deg(gps.get(2), gps.get(1), ("S",)), deg(gps.get(4), gps.get(3), ("W",)), alt


def read_photo(path: str | Path, *, geoid=None, data: bytes | None = None) -> PhotoPose:
    """The :class:`PhotoPose` of a drone photo; a :class:`PhotoError` naming the file, the tag and
    the fix when it cannot be read. ``data``: the photo's bytes (as an HTTP request brings them),
    ``path`` then only its name in messages and rows. Only the metadata is read, not the pixels."""
    import io

    from PIL import Image, UnidentifiedImageError

    path = str(path)
    try:
        with Image.open(path if data is None else io.BytesIO(data)) as im:
            width, height = im.size
            exif = im.getexif()
            raw = raw_xmp(im)
    except FileNotFoundError:
        raise PhotoError(f"{path}: no such file") from None
    except UnidentifiedImageError:
        raise PhotoError(f"{path}: not an image Pillow can read (give the drone's JPEG or TIFF as it was taken)") \
            from None
    except OSError as exc:
        raise PhotoError(f"{path}: the image cannot be read ({exc}): truncated or damaged?") from None
    try:
        xmp = parse_xmp(raw)
    except PhotoError as exc:
        raise PhotoError(f"{path}: {exc}") from None
    tiff = xmp.get("tiff", {})
    make = str(tiff.get("Make") or exif.get(271) or "").strip().strip("\x00")
    model = str(tiff.get("Model") or exif.get(272) or "").strip().strip("\x00")
    photo = Photo(path, make, model, width, height, exif, xmp, geoid)
    dji = xmp.get("dji", {})
    if dji:
        return _dji(photo, dji)
    for vendor, reader in (("skydio", _skydio), ("parrot", _parrot), ("pix4d", _pix4d)):
        if xmp.get(vendor):
            return reader(photo, xmp[vendor])
    if "PlatformYaw" in xmp.get("exif", {}) or "CameraYaw" in xmp.get("exif", {}):
        return _teal(photo, xmp["exif"])
    name = make or "unknown make"
    if not raw:
        raise PhotoError(f"{path}: no XMP drone tags ({name} {model}): eoloc reads the camera's pose from the "
                         "drone's XMP (DJI drone-dji:, Skydio drone-skydio:, Parrot drone-parrot:, Autel Camera:, Teal "
                         "exif:Platform*); was the photo exported or re-saved without its metadata?")
    raise PhotoError(f"{path}: its XMP holds no drone pose eoloc knows ({name} {model}: none of the DJI, Skydio, "
                     "Parrot, Autel or Teal tags); give its pose as a telemetry CSV to eoloc locate")


@dataclass(frozen=True)
class Photo:
    """What every vendor's reader starts from."""

    path: str
    make: str
    model: str
    width: int
    height: int
    exif: object
    xmp: dict
    geoid: object

    def undulation(self, lat: float, lon: float) -> float:
        from ..terrain.geoid import default_geoid

        return float((self.geoid or default_geoid()).undulation(lat, lon))

    def position(self, tags: dict | None = None, lat_key: str = "", lon_key: str = "") -> tuple[float, float, list]:
        """(lat, lon, notes) from the vendor's tags when it has them, else EXIF GPS."""
        notes: list[str] = []
        lat = _num(tags, lat_key, self.path, required=False) if tags and lat_key else None
        lon = _num(tags, lon_key, self.path, required=False) if tags and lon_key else None
        if lat is None or lon is None:
            lat, lon = _exif_gps(self.exif)
            if lat is None or lon is None:
                where = f"XMP {lat_key}/{lon_key} nor " if lat_key else ""
                raise PhotoError(f"{self.path}: no position: neither {where}EXIF GPS")
            if lat_key:
                notes.append("position from EXIF GPS (the XMP has none)")
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise PhotoError(f"{self.path}: position {lat!r}, {lon!r} is not a latitude/longitude")
        return lat, lon, notes

    def exif_height(self, lat: float, lon: float, *, msl: bool, why: str) -> tuple[float, str]:
        """EXIF GPSAltitude as an ellipsoidal height (``msl``: above EGM96, converted) and the rule said."""
        alt = _exif_gps_3d(self.exif)[2]
        if alt is None or not math.isfinite(alt):
            raise PhotoError(f"{self.path}: no height: EXIF GPSAltitude is missing")
        if msl:
            n = self.undulation(lat, lon)
            return alt + n, f"EXIF GPSAltitude {alt:g} m above the EGM96 geoid ({why}) + N {n:.2f} m"
        return alt, f"EXIF GPSAltitude {alt:g} m above the WGS-84 ellipsoid ({why})"

    def finish(self, vendor: str, lat, lon, h, rule, yaw, pitch, roll, *, calib: dict, thermal: bool,
               notes: list, **more) -> PhotoPose:
        """The pose with its camera (:func:`eoloc.sensor.dronemodels.camera_for`)."""
        from ..sensor import dronemodels

        if yaw == 0.0 and pitch == 0.0 and roll == 0.0:
            raise PhotoError(f"{self.path}: the camera's yaw, pitch and roll are all 0: this drone writes 0 when it "
                             "does not know the camera's attitude (DJI Mini 2 does); give the pose as a telemetry CSV "
                             "to eoloc locate instead")
        camera, source = dronemodels.camera_for(self.make or vendor, self.model, self.width, self.height,
                                                thermal=thermal, tags=calib, exif=self.exif, path=self.path)
        if source.startswith("EXIF"):
            notes.append(f"intrinsics from {source}: approximate (no calibrated values, model not in the database)")
        time = str(self.exif.get(306) or "") or None
        return PhotoPose(self.path, vendor, self.make or vendor, self.model, self.width, self.height, lat, lon, h, rule,
                         yaw, pitch, roll, camera, source, thermal, time=more.pop("time", None) or time,
                         notes=notes, **more)


def _dji(p: Photo, tags: dict) -> PhotoPose:
    path = p.path
    lat, lon, notes = p.position(tags, "GpsLatitude", "GpsLongitude")
    alt = _num(tags, "AbsoluteAltitude", path)
    version = str(tags.get("Version", "0")).strip()
    rtk = str(tags.get("GpsStatus", "")).strip().upper() == "RTK" or (_num(tags, "RtkFlag", path, required=False)
                                                                        or 0) > 0
    autel = "autel" in p.make.lower()
    to_ell = 0.0
    if autel:
        h, rule = alt, f"AbsoluteAltitude {alt:g} m taken as above the WGS-84 ellipsoid (Autel's drone-dji tags, as " \
                       "OpenAthena reads them)"
    elif _version(version) < (1, 5) and not rtk:
        to_ell = p.undulation(lat, lon)
        h = alt + to_ell
        rule = (f"AbsoluteAltitude {alt:g} m above the EGM96 geoid (XMP Version {version} < 1.5, no RTK) + N "
                f"{to_ell:.2f} m")
    else:
        h = alt
        rule = (f"AbsoluteAltitude {alt:g} m above the WGS-84 ellipsoid (XMP Version {version}"
                + (", RTK" if rtk else "") + ")")
    yaw = _num(tags, "GimbalYawDegree", path)
    pitch = _num(tags, "GimbalPitchDegree", path)
    roll = _num(tags, "GimbalRollDegree", path, required=False) or 0.0
    thermal = str(tags.get("ImageSource", "")).lower().startswith("infrared") or \
        str(tags.get("BandName", "")).upper().find("LWIR") >= 0
    lrf = lrf_target = None
    d = _num(tags, "LRFTargetDistance", path, required=False)
    if d is not None and d > 0 and str(tags.get("LRFStatus", "Normal")).strip().lower() == "normal":
        lrf = d
        t_lat = _num(tags, "LRFTargetLat", path, required=False)
        t_lon = _num(tags, "LRFTargetLon", path, required=False)
        t_alt = _num(tags, "LRFTargetAbsAlt", path, required=False)
        if None not in (t_lat, t_lon, t_alt):
            lrf_target = (t_lat, t_lon, t_alt + (p.undulation(t_lat, t_lon) if to_ell else 0.0))
    return p.finish("Autel" if autel else "DJI", lat, lon, h, rule, yaw, pitch, roll, calib=tags, thermal=thermal,
                    notes=notes, relative_altitude_m=_num(tags, "RelativeAltitude", path, required=False),
                    lrf_range_m=lrf, lrf_target=lrf_target, time=str(tags.get("CreateDate") or "") or None)


def _skydio(p: Photo, tags: dict) -> PhotoPose:
    path = p.path
    lat, lon, notes = p.position(tags, "Latitude", "Longitude")
    alt = _num(tags, "AbsoluteAltitude", path, required=False)
    if alt is not None:
        n = p.undulation(lat, lon)
        h = alt + n
        rule = f"AbsoluteAltitude {alt:g} m above the EGM96 geoid (Skydio, as OpenAthena reads it) + N {n:.2f} m"
    else:
        h, rule = p.exif_height(lat, lon, msl=False, why="Skydio's X10 metadata overview")
    yaw = _num(tags, "CameraOrientationNED.Yaw", path)
    pitch = _num(tags, "CameraOrientationNED.Pitch", path)
    roll = _num(tags, "CameraOrientationNED.Roll", path, required=False) or 0.0
    thermal = "thermal" in p.model.lower() or p.model.endswith("_40")
    return p.finish("Skydio", lat, lon, h, rule, yaw, pitch, roll, calib=tags, thermal=thermal, notes=notes)


def _parrot(p: Photo, tags: dict) -> PhotoPose:
    lat, lon, notes = p.position()
    ai = "anafiai" in p.model.lower().replace(" ", "")
    h, rule = p.exif_height(lat, lon, msl=not ai, why="ANAFI Ai: ellipsoidal" if ai else
                            "ANAFI 4K/Thermal/USA: EGM96, Parrot's photo metadata reference")
    yaw = _num(tags, "CameraYawDegree", p.path)
    pitch = _num(tags, "CameraPitchDegree", p.path)
    roll = _num(tags, "CameraRollDegree", p.path, required=False) or 0.0
    thermal = "thermal" in p.model.lower() and p.width <= 640
    return p.finish("Parrot", lat, lon, h, rule, yaw, pitch, roll, calib={}, thermal=thermal, notes=notes)


def _pix4d(p: Photo, tags: dict) -> PhotoPose:
    lat, lon, notes = p.position()
    h, rule = p.exif_height(lat, lon, msl=True, why="older Autel firmware: says ellipsoidal, is not (OpenAthena)")
    yaw = _num(tags, "Yaw", p.path)
    pitch = _num(tags, "Pitch", p.path) - 90.0  # Pix4D's Camera:Pitch is 0 at nadir, 90 at the horizon
    roll = _num(tags, "Roll", p.path, required=False) or 0.0
    return p.finish("Autel", lat, lon, h, rule, yaw, pitch, roll, calib={}, thermal=False, notes=notes)


def _teal(p: Photo, tags: dict) -> PhotoPose:
    lat, lon, notes = p.position()
    h, rule = p.exif_height(lat, lon, msl=True, why="Teal, as OpenAthena reads it")

    def total(axis: str, required: bool = True) -> float:
        a = _num(tags, f"Platform{axis}", p.path, required=required)
        b = _num(tags, f"Camera{axis}", p.path, required=required)
        return (a or 0.0) + (b or 0.0)

    return p.finish("Teal", lat, lon, h, rule + "; attitude = platform + camera angles", total("Yaw"), total("Pitch"),
                    total("Roll", required=False), calib={}, thermal=False, notes=notes)


def _version(v: str) -> tuple[int, ...]:
    out = []
    for part in v.split("."):
        digits = "".join(ch for ch in part if ch.isdigit())
        out.append(int(digits) if digits else 0)
    return tuple(out)


#: eoloc photo --json's pose keys and the PhotoPose fields (= the photo telemetry table's columns) they are
POSE_FIELDS = {"camera_lat": "lat_deg", "camera_lon": "lon_deg", "camera_h": "h_m", "camera_yaw": "yaw_deg",
               "camera_pitch": "pitch_deg", "camera_roll": "roll_deg"}
POSE_KEYS = tuple(POSE_FIELDS)


def read_photo_poses(path: str | Path) -> dict[str, dict[str, float]]:
    """Poses that replace the photos' own: {photo file name: {camera_lat ... camera_roll}} from
    ``eoloc refine PHOTO...``'s photos_refined.csv, or its --json lines (``file`` and
    :data:`POSE_KEYS`, eoloc photo --json's names: degrees, ellipsoidal metres). A
    :class:`PhotoError` names the file, the line and the key when one is missing or not a number."""
    import csv
    import json

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise PhotoError(f"{path}: the photos' poses cannot be read ({exc})") from None
    if text.lstrip().startswith("{"):
        try:
            rows = [(i, json.loads(line)) for i, line in enumerate(text.splitlines(), 1) if line.strip()]
        except json.JSONDecodeError as exc:
            raise PhotoError(f"{path}: line {exc.lineno}: not JSON ({exc.msg})") from None
    else:
        rows = list(enumerate(csv.DictReader(text.splitlines()), 2))
    out: dict[str, dict[str, float]] = {}
    for line, row in rows:
        missing = [k for k in ("file", *POSE_KEYS) if row.get(k) in (None, "")]
        if missing:
            raise PhotoError(f"{path}:{line}: no {', '.join(missing)} (give eoloc refine's photos_refined.csv, "
                             "or its --json lines)")
        try:
            pose = {k: float(row[k]) for k in POSE_KEYS}
        except (TypeError, ValueError):
            raise PhotoError(f"{path}:{line}: {', '.join(POSE_KEYS)} must be numbers") from None
        if not all(math.isfinite(v) for v in pose.values()) or abs(pose["camera_lat"]) > 90:
            raise PhotoError(f"{path}:{line}: a pose value is not finite, or the latitude is past 90 degrees")
        out[Path(str(row["file"])).name] = pose
    if not out:
        raise PhotoError(f"{path}: no photo pose in it (give eoloc refine's photos_refined.csv, or its --json lines)")
    return out
