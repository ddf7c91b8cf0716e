"""Convention check: when eoloc's frame centres or VMTI locations disagree with the encoder's, try
the documented alternative readings (:data:`eoloc.io.klv.conventions.CONVENTIONS`) and say which
one the encoder follows, with the agreement under each.

Frame centres: every combination of earth-referenced sensor angles and swapped sensor and
frame-centre height datums, each stopped at the encoder's frame-centre elevation and (where tag
21 is sent) at the slant range. VMTI: pixel numbers from 1 (ST 0903) or 0, and the target
location datum HAE (ST 0903) or MSL. A reading is named only when it is clearly better: its median
distance is under half the standard reading's and the standard reading is off by more than
``threshold_m``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ..geodesy import horizontal_distance_m
from ..ground.frame import frame_centre, misb_sensor, packet_heights, packet_pose
from ..io.klv.conventions import CONVENTIONS, FRAME_CONVENTIONS, apply_to_telemetry, encoder_heights_hae
from ..io.records import Records

THRESHOLD_M = 50.0


@dataclass(frozen=True)
class Trial:
    """One reading of the stream: the conventions assumed, the stop used, and how far eoloc's points
    are from the encoder's under it (n compared, median and p90, metres)."""

    assume: tuple[str, ...]
    stop: str
    n: int
    median_m: float
    p90_m: float

    @property
    def label(self) -> str:
        return " + ".join(self.assume) if self.assume else "as the standard says"


@dataclass(frozen=True)
class Diagnosis:
    """The trials for one quantity (frame centre, VMTI location, VMTI height), best first, and the
    verdict: the reading the encoder follows when it is clearly not the standard's, else None."""

    what: str
    trials: list[Trial]
    best: Trial | None = None
    standard: Trial | None = None
    follows: Trial | None = None
    threshold_m: float = THRESHOLD_M

    @property
    def disagrees(self) -> bool:
        """The standard reading is further from the encoder than the threshold."""
        s = self.standard
        return s is not None and s.n > 0 and s.median_m > self.threshold_m

    def sentence(self) -> str:
        s = self.standard
        if s is None or s.n == 0:
            return f"{self.what}: nothing to compare (the encoder sends none)"
        if self.follows is None and not self.disagrees:
            return (f"{self.what}: the encoder agrees with the standard reading (median {s.median_m:.1f} m over "
                    f"{s.n})")
        if self.follows is None:
            b = self.best
            other = (f"; the closest alternative, {b.label}, still gives {b.median_m:.1f} m" if b is not None and
                     b is not s else "")
            return (f"{self.what}: the encoder is {s.median_m:.1f} m from eoloc (median over {s.n}) under the "
                    f"standard reading, and no documented alternative explains it{other}: check the installation "
                    "angles, the time alignment of the tags and the encoder's own model")
        f = self.follows
        how = " ".join(f"--assume {a}" for a in f.assume)
        stop = " along the slant range" if f.stop == "slant range" else ""
        return (f"{self.what}: the encoder follows {f.label}{stop} (median {f.median_m:.1f} m) rather than the "
                f"standard (median {s.median_m:.1f} m)" + (f"; apply it with {how}" if how else ""))


def _stats(d: np.ndarray) -> tuple[int, float, float]:
    d = d[np.isfinite(d)]
    if not d.size:
        return 0, np.nan, np.nan
    return int(d.size), float(np.median(d)), float(np.percentile(d, 90))


def _verdict(what: str, trials: list[Trial], threshold_m: float) -> Diagnosis:
    standard = next((t for t in trials if not t.assume and t.stop != "slant range"), None)
    usable = [t for t in trials if t.n and (standard is None or t.n >= 0.5 * standard.n)]
    usable.sort(key=lambda t: t.median_m)
    best = usable[0] if usable else None
    follows = None
    if best is not None and standard is not None and standard.n and best is not standard \
            and standard.median_m > threshold_m and best.median_m < max(threshold_m, 0.1 * standard.median_m):
        follows = best  # it explains the disagreement, not merely shrinks it
    order = sorted(trials, key=lambda t: (not t.n, t.median_m if t.n else 0.0))
    return Diagnosis(what, order, best, standard, follows, threshold_m)


def diagnose_frames(tel, sensor=None, *, threshold_m: float = THRESHOLD_M) -> Diagnosis:
    """eoloc's frame centres against the encoder's (tags 23/24): the standard reading, and when it is
    off by more than ``threshold_m`` every combination of the frame conventions, stopped at the
    encoder's frame-centre elevation and at the slant range."""
    sensor = sensor or misb_sensor()
    c = tel.columns
    trials: list[Trial] = []
    for k in range(len(FRAME_CONVENTIONS) + 1):
        if k == 1 and not (trials and trials[0].n and trials[0].median_m > threshold_m):
            break  # the standard reading agrees (or nothing to compare): no alternative is tried
        for assume in combinations(FRAME_CONVENTIONS, k):
            t = apply_to_telemetry(tel, assume)
            tc = t.columns
            for stop in ("frame-centre elevation", "slant range"):
                if stop == "slant range":
                    if "centre-datum-swapped" in assume:
                        continue  # the frame-centre height plays no part along the range
                    with np.errstate(invalid="ignore"):
                        rng = np.where(tc["range_m"] > 0, tc["range_m"], np.nan)
                    if not np.isfinite(rng).any():
                        continue
                    centre = frame_centre(sensor, packet_pose(t), None, range_m=rng)
                else:
                    centre = frame_centre(sensor, packet_pose(t), packet_heights(tc["fc_h_m"]))
                d = horizontal_distance_m(centre.lat_deg, centre.lon_deg, c["fc_lat_deg"], c["fc_lon_deg"])
                trials.append(Trial(assume, stop, *_stats(d)))
    return _verdict("frame centre", trials, threshold_m)


def diagnose_vmti(det, fixes, other, *, assume=(), threshold_m: float = 0.5) -> list[Diagnosis]:
    """eoloc's VMTI fixes against the encoder's own target locations: horizontally for the pixel
    numbering in use (``det``/``fixes``) and, when that is off by more than ``threshold_m``, the
    other one (``other()`` -> (detections, fixes) with ST 0903 pixel numbers read from 0 instead
    of 1, or back); vertically for the location datum HAE and MSL."""
    base = tuple(a for a in assume if a not in ("vmti-pixels-from-0", "vmti-msl"))
    from_0 = "vmti-pixels-from-0" in assume

    def trial(d, f, zero: bool) -> Trial:
        ok = np.asarray(f.ok)
        dist = horizontal_distance_m(np.where(ok, f.lat_deg, np.nan), f.lon_deg, d.columns["encoder_lat_deg"],
                                     d.columns["encoder_lon_deg"])
        return Trial(base + (("vmti-pixels-from-0",) if zero else ()), "as located", *_stats(dist))

    pix = [trial(det, fixes, from_0)]
    if pix[0].n and pix[0].median_m > threshold_m:
        pix.append(trial(*other(), not from_0))
    ok = np.asarray(fixes.ok)
    heights = []
    for msl in (False, True):
        h_enc = encoder_heights_hae(det, ("vmti-msl",) if msl else ())
        heights.append(Trial(base + (("vmti-msl",) if msl else ()), "as located",
                             *_stats(np.abs(np.where(ok, fixes.h_m, np.nan) - h_enc))))
    return [_verdict("VMTI target location (horizontal)", pix, threshold_m),
            _verdict("VMTI target height", heights, 1.0)]


def diagnosis_records(diagnoses: list[Diagnosis]) -> Records:
    """conventions.csv: one row per trial."""
    rows = []
    for dg in diagnoses:
        for t in dg.trials:
            rows.append({"quantity": dg.what, "reading": t.label, "assume": " ".join(t.assume), "stop": t.stop,
                         "n": t.n, "median_m": t.median_m, "p90_m": t.p90_m,
                         "encoder_follows": int(t is dg.follows), "standard": int(t is dg.standard)})
    return Records.from_rows(rows)


__all__ = ["CONVENTIONS", "Diagnosis", "Trial", "diagnose_frames", "diagnose_vmti", "diagnosis_records"]
