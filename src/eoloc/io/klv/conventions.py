"""The documented ways encoders depart from ST 0601 / ST 0903, as adapters on the decoded tables.

Each convention is a name a user can pass (``eoloc klv --assume NAME``) and a pure function of
the telemetry and detections tables; the convention check of `eoloc klv` tries them and reports
which one the encoder follows. Nothing here changes what the reader decodes; eoloc applies the
standard unless told otherwise.
"""

from __future__ import annotations

import numpy as np

from ..table import Table

CONVENTIONS: dict[str, str] = {
    "earth-angles": "sensor azimuth/elevation/roll (tags 18-20) are earth-referenced (azimuth from true north, "
                    "elevation from the horizontal), not relative to the platform: platform attitude not applied",
    "sensor-datum-swapped": "the sensor height tag holds the other datum (tag 15 holds HAE, or tag 75 MSL)",
    "centre-datum-swapped": "the frame-centre height tag holds the other datum (tag 25 holds HAE, or tag 78 MSL)",
    "vmti-pixels-from-0": "ST 0903 pixel numbers, rows and columns count from 0, not 1",
    "vmti-msl": "ST 0903 target locations (tag 17, or height tag 12) are MSL, not HAE",
}
FRAME_CONVENTIONS = ("earth-angles", "sensor-datum-swapped", "centre-datum-swapped")


def _swap_datum(h: np.ndarray, h_msl: np.ndarray, undulation: np.ndarray) -> np.ndarray:
    """Ellipsoidal heights read the other way: from an MSL tag (h = H + N) -> H as HAE; from an
    HAE tag (no MSL value) -> h + N."""
    from_msl = np.isfinite(h_msl) & np.isclose(h, h_msl + undulation, atol=1e-6)
    return np.where(from_msl, h_msl, h + undulation)


def apply_to_telemetry(tel: Table, names, *, geoid=None) -> Table:
    """The telemetry table read under the conventions ``names`` (a new table; columns copied)."""
    from ...terrain.geoid import default_geoid

    names = set(names)
    if not names & set(FRAME_CONVENTIONS):
        return tel
    geoid = geoid or default_geoid()
    c = dict(tel.columns)
    if "earth-angles" in names:
        zero = np.zeros(len(tel))
        c["yaw_deg"], c["pitch_deg"], c["roll_deg"] = zero, zero.copy(), zero.copy()
    if "sensor-datum-swapped" in names and len(tel):
        c["h_m"] = _swap_datum(c["h_m"], c["h_msl_m"], geoid.undulation(c["lat_deg"], c["lon_deg"]))
    if "centre-datum-swapped" in names and len(tel):
        c["fc_h_m"] = _swap_datum(c["fc_h_m"], c["fc_h_msl_m"], geoid.undulation(c["fc_lat_deg"], c["fc_lon_deg"]))
    return Table(tel.path, c, tel.line, tel.issues)


def encoder_heights_hae(det: Table, names, *, geoid=None) -> np.ndarray:
    """The encoder's VMTI target heights as HAE (ST 0903's datum; converted from MSL under vmti-msl)."""
    from ...terrain.geoid import default_geoid

    h = det.columns["encoder_h_m"]
    if "vmti-msl" not in set(names) or not len(det):
        return h
    geoid = geoid or default_geoid()
    return h + geoid.undulation(det.columns["encoder_lat_deg"], det.columns["encoder_lon_deg"])
