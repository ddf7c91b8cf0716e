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

Other vendors (Skydio ``drone-skydio:``, Autel, Parrot ``drone-parrot:``, Teal) are named and
refused with what is missing, until their readers land.
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
    raw = xmp.get(key)
    if raw is None or (isinstance(raw, str) and not raw.strip()):
        if required:
            raise PhotoError(f"{path}: the XMP has no {key}: eoloc cannot place the camera without it (a photo "
                             "re-saved by an editor may have lost its drone tags: use the original file)")
        return None
    try:
        v = float(str(raw).strip())
    except ValueError:
        raise PhotoError(f"{path}: XMP {key} = {raw!r} is not a number") from None
    if not math.isfinite(v):
        raise PhotoError(f"{path}: XMP {key} = {raw!r} is not a finite number")
    return v


def _description(xmp: dict) -> dict:
    """The flat tags of the XMP's rdf:Description (Pillow gives nested dicts; several Descriptions
    are merged)."""
    try:
        desc = xmp["xmpmeta"]["RDF"]["Description"]
    except (KeyError, TypeError):
        return {}
    if isinstance(desc, list):
        out: dict = {}
        for d in desc:
            if isinstance(d, dict):
                out.update(d)
        return out
    return desc if isinstance(desc, dict) else {}


def _exif_gps(exif) -> tuple[float | None, float | None]:
    try:
        gps = exif.get_ifd(0x8825)
    except Exception:
        return None, None

    def deg(values, ref, neg):
        if not values or len(values) != 3:
            return None
        d, m, s = (float(x) for x in values)
        v = d + m / 60.0 + s / 3600.0
        return -v if ref in neg else v

    return deg(gps.get(2), gps.get(1), ("S",)), deg(gps.get(4), gps.get(3), ("W",))


def read_photo(path: str | Path, *, geoid=None) -> PhotoPose:
    """The :class:`PhotoPose` of a drone photo; a :class:`PhotoError` naming the file, the tag and
    the fix when it cannot be read."""
    import warnings

    from PIL import Image, UnidentifiedImageError

    path = str(path)
    try:
        with Image.open(path) as im:
            width, height = im.size
            exif = im.getexif()
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # "XMP data cannot be read without defusedxml" is a missing dependency
                xmp = im.getxmp() if hasattr(im, "getxmp") else {}
    except FileNotFoundError:
        raise PhotoError(f"{path}: no such file") from None
    except UnidentifiedImageError:
        raise PhotoError(f"{path}: not an image Pillow can read (give the drone's JPEG or TIFF as it was taken)") \
            from None
    except OSError as exc:
        raise PhotoError(f"{path}: the image cannot be read ({exc}): truncated or damaged?") from None
    tags = _description(xmp)
    make = str(tags.get("Make") or exif.get(271) or "").strip()
    model = str(tags.get("Model") or exif.get(272) or "").strip()
    if "GimbalYawDegree" in tags or "GimbalPitchDegree" in tags or str(tags.get("about", "")).startswith("DJI"):
        return _dji(path, tags, exif, make or "DJI", model, width, height, geoid)
    vendor = make or "unknown"
    if not tags:
        raise PhotoError(f"{path}: no XMP drone tags ({vendor} {model}): eoloc reads the camera's pose from the "
                         "drone's XMP (DJI drone-dji:...); was the photo exported or re-saved without its metadata?")
    known = {"skydio": "Skydio", "autel": "Autel", "parrot": "Parrot", "teal": "Teal"}
    name = next((v for k, v in known.items() if k in vendor.lower()), vendor)
    raise PhotoError(f"{path}: {name} photos are not read yet (only DJI's drone-dji: tags); its pose can be given "
                     "as a telemetry CSV to eoloc locate")


def _dji(path, tags, exif, make, model, width, height, geoid) -> PhotoPose:
    from ..sensor import dronemodels

    notes: list[str] = []
    lat = _num(tags, "GpsLatitude", path, required=False)
    lon = _num(tags, "GpsLongitude", path, required=False)
    if lat is None or lon is None:
        lat, lon = _exif_gps(exif)
        if lat is None or lon is None:
            raise PhotoError(f"{path}: no position: neither XMP GpsLatitude/GpsLongitude nor EXIF GPS")
        notes.append("position from EXIF GPS (the XMP has none)")
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise PhotoError(f"{path}: position {lat!r}, {lon!r} is not a latitude/longitude")
    alt = _num(tags, "AbsoluteAltitude", path)
    version = str(tags.get("Version", "0")).strip()
    rtk = str(tags.get("GpsStatus", "")).strip().upper() == "RTK" or (_num(tags, "RtkFlag", path, required=False)
                                                                        or 0) > 0
    older = _version(version) < (1, 5)
    if older and not rtk:
        from ..terrain.geoid import default_geoid

        n = float((geoid or default_geoid()).undulation(lat, lon))
        h = alt + n
        rule = f"AbsoluteAltitude {alt:g} m above the EGM96 geoid (XMP Version {version} < 1.5, no RTK) + N {n:.2f} m"
        to_ell = n
    else:
        h = alt
        rule = (f"AbsoluteAltitude {alt:g} m above the WGS-84 ellipsoid (XMP Version {version}"
                + (", RTK" if rtk else "") + ")")
        to_ell = 0.0
    yaw = _num(tags, "GimbalYawDegree", path)
    pitch = _num(tags, "GimbalPitchDegree", path)
    roll = _num(tags, "GimbalRollDegree", path, required=False) or 0.0
    if yaw == 0.0 and pitch == 0.0 and roll == 0.0:
        raise PhotoError(f"{path}: GimbalYawDegree, GimbalPitchDegree and GimbalRollDegree are all 0: this drone "
                         "writes 0 when it does not know the camera's attitude (DJI Mini 2 does); give the pose as a "
                         "telemetry CSV to eoloc locate instead")
    thermal = str(tags.get("ImageSource", "")).lower().startswith("infrared") or \
        str(tags.get("BandName", "")).upper().find("LWIR") >= 0
    camera, source = dronemodels.camera_for(make, model, width, height, thermal=thermal, tags=tags, exif=exif,
                                            path=path)
    if source.startswith("EXIF"):
        notes.append(f"intrinsics from {source}: approximate (no calibrated values, model not in the database)")
    lrf = lrf_target = None
    d = _num(tags, "LRFTargetDistance", path, required=False)
    if d is not None and d > 0 and str(tags.get("LRFStatus", "Normal")).strip().lower() == "normal":
        lrf = d
        t_lat = _num(tags, "LRFTargetLat", path, required=False)
        t_lon = _num(tags, "LRFTargetLon", path, required=False)
        t_alt = _num(tags, "LRFTargetAbsAlt", path, required=False)
        if None not in (t_lat, t_lon, t_alt):
            if to_ell:
                from ..terrain.geoid import default_geoid

                to_ell = float((geoid or default_geoid()).undulation(t_lat, t_lon))
            lrf_target = (t_lat, t_lon, t_alt + to_ell)
    return PhotoPose(path, "DJI", make, model, width, height, lat, lon, h, rule, yaw, pitch, roll, camera, source,
                     thermal, _num(tags, "RelativeAltitude", path, required=False), lrf, lrf_target,
                     str(tags.get("CreateDate") or exif.get(306) or "") or None, notes)


def _version(v: str) -> tuple[int, ...]:
    out = []
    for part in v.split("."):
        digits = "".join(ch for ch in part if ch.isdigit())
        out.append(int(digits) if digits else 0)
    return tuple(out)
