"""The `eoloc klv` job: a MISB ST 0601 stream decoded, checked against the encoder's own frame
geometry, its ST 0903 VMTI targets located; and the writer of its products."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import KLVError
from ..io.export import STATUS_NAMES, fix_features, fix_records, utc_times, with_utc
from ..io.records import Records
from ..rules import OnDEM


@dataclass
class KLVJob:
    """Everything `eoloc klv` computes: the decoded stream, its telemetry table (under the assumed
    conventions), the frame check, the VMTI detections and their fixes (None without VMTI), fix
    records, the GeoJSON layers (aircraft, footprints, encoder footprints, fixes) and the
    convention check."""

    path: Path
    stream: object
    telemetry: object
    check: object
    detections: object
    vmti: object | None
    records: Records
    layers: dict[str, list[dict]]
    dem: object | None = None
    issues: list = field(default_factory=list)
    diagnoses: list = field(default_factory=list)
    assume: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)  # why most targets or every footprint failed
    footprint_table: tuple[Records, object] | None = None  # (properties, WKBColumn of polygons): the archive's form

    @property
    def has_footprint(self) -> bool:
        """At least one frame's footprint was drawn."""
        return footprint_drawn(self.layers["footprints"], self.footprint_table)

    @property
    def located_nothing(self) -> bool:
        """The stream has VMTI targets, and neither one of them nor one footprint was located: the
        run gave nothing on the ground. (A stream without targets read for its telemetry and
        checks is not a failed run, whatever its footprints: their note says why they are missing.)"""
        if self.vmti is None or bool(self.vmti.fixes.ok.any()):
            return False
        return not self.has_footprint

    @property
    def surface(self) -> str:
        return "the DEM" if self.dem is not None else "the frame-centre elevation"


def footprint_drawn(features: list[dict], table: tuple | None = None) -> bool:
    """At least one footprint has a geometry: among GeoJSON ``features``, or the polygons of a
    (properties, geometries) ``table`` where there is one."""
    if table is not None:
        return table[1].drawn
    return any(f.get("geometry") for f in features)


def klv_job(path, *, dem=None, sensor=None, budget=None, footprint_every: int = 1, strict: bool = False,
            assume=(), map_layers: bool = True) -> KLVJob:
    """Decode ``path`` (raw KLV or MPEG-TS), recompute every frame's centre and corners, locate the
    VMTI detections on ``dem`` or the frame-centre elevation (with uncertainty from ``budget``),
    and check which conventions the encoder follows. strict: packets that break ST 0601 are
    dropped (named); assume: convention names (:data:`eoloc.io.klv.conventions.CONVENTIONS`)
    applied to the stream before anything is computed. map_layers=False leaves out the GeoJSON
    layers only the map and KML draw (aircraft, encoder footprints, fixes): an archive job's saving.
    (The archive's form, on columns, a segment at a time: :func:`klv_segment_jobs`.)"""
    from ..io.klv import read_klv

    stream = read_klv(path, strict=strict)
    return stream_job(path, stream, dem=dem, sensor=sensor, budget=budget, footprint_every=footprint_every,
                      assume=assume, map_layers=map_layers)


@dataclass
class RangeStart:
    """What a byte range of a KLV file needs from the bytes before it to read and locate as one
    reading of the whole file would: the packets numbered before it, the telemetry rows before it
    (the footprints' every-n-th count), and what a receiver knew at its start (report-on-change
    items, the VMTI frame size: :func:`eoloc.io.klv.tables.carried_state`; None at the file's
    start). Found by :func:`range_starts` from every range's :func:`range_summary`."""

    first_index: int = 0
    rows: int = 0
    state: object | None = None


def range_summary(path, span: tuple[int, int], *, segment_bytes: int | None = None, strict: bool = False
                  ) -> tuple[int, int, object | None]:
    """A byte range of a raw KLV file read on its own (no location): the packets numbered in it
    (good and bad), the good ones (a telemetry row each), and what a receiver knows at its end
    from it alone (:func:`eoloc.io.klv.tables.carried_state`; None: no good packet)."""
    from ..io.klv.segments import SEGMENT_BYTES, klv_segments
    from ..io.klv.tables import carried_state, with_state

    packets, good, state = 0, 0, None
    for seg in klv_segments(path, segment_bytes=segment_bytes or SEGMENT_BYTES, strict=strict, span=span):
        packets, good = packets + len(seg) + seg.n_bad, good + len(seg)
        if len(seg):
            state = carried_state(with_state(seg, state))
    return packets, good, state


def range_starts(summaries: list[tuple[int, int, object | None]]) -> list[RangeStart]:
    """Each range's :class:`RangeStart` from the :func:`range_summary` of every range, in file
    order: packets and rows summed over the ranges before it, the state folded (each item's last
    value wins, as it does packet by packet)."""
    from ..io.klv.tables import carried_state, with_state

    out, start = [], RangeStart()
    for packets, good, state in summaries:
        out.append(start)
        folded = start.state if state is None else carried_state(with_state(state, start.state))
        start = RangeStart(start.first_index + packets, start.rows + good, folded)
    return out


def klv_segment_jobs(path, *, segment_bytes: int | None = None, dem=None, sensor=None, budget=None,
                     footprint_every: int = 1, strict: bool = False, assume=(), span: tuple[int, int] | None = None,
                     start: RangeStart | None = None) -> Iterator[tuple[object, KLVJob | None]]:
    """:func:`klv_job` (columnar, without the map's layers or the convention checks) a segment of
    the file at a time (:func:`eoloc.io.klv.segments.klv_segments`: memory bounded by
    ``segment_bytes``, whatever the file's size): (the segment's columns, its job) in file order,
    the job None for a segment with no good packet (its issues are the columns'). Report-on-change,
    the VMTI frame size and the footprints' every-n-th count are carried from segment to segment,
    so the rows are those of the whole file's job wherever the stream's time runs forward across
    the cuts. Raises :class:`KLVError` as :func:`klv_job` does, once the file is read, when no
    packet was good. ``span``: a byte range of a raw KLV file only, begun from ``start`` (what
    the bytes before it leave); then no packet is no error."""
    from ..io.klv.segments import SEGMENT_BYTES, klv_segments
    from ..io.klv.tables import carried_state, with_state

    start = start or RangeStart()
    state, rows, good, issues = start.state, start.rows, 0, []
    every = max(footprint_every, 1)
    for seg in klv_segments(path, segment_bytes=segment_bytes or SEGMENT_BYTES, strict=strict, span=span,
                            first_index=start.first_index):
        if not len(seg):
            issues += seg.issues
            yield seg, None
            continue
        carried = with_state(seg, state)
        job = stream_job(path, seg, dem=dem, sensor=sensor, budget=budget, footprint_every=every, assume=assume,
                         map_layers=False, carried=carried, first_footprint=(-rows) % every, diagnose=False)
        state = carried_state(carried)
        rows, good = rows + len(job.telemetry), good + len(seg)
        yield seg, job
    if not good and span is None:
        raise KLVError(f"{path}: no packet could be decoded, so there is nothing to locate", [str(i) for i in issues])


def stream_job(path, stream, *, dem=None, sensor=None, budget=None, footprint_every: int = 1, assume=(),
               map_layers: bool = True, carried=None, first_footprint: int = 0, diagnose: bool = True) -> KLVJob:
    """:func:`klv_job` of a stream already read (objects, or columns: then its footprints on the
    frame-centre elevation as a table, ``footprint_table``, the archive's form); ``carried``: a
    segment of a longer file, the stream's columns with what the packets before it left put in front
    (:func:`eoloc.io.klv.tables.with_state`); ``first_footprint``: the first row whose footprint is
    drawn; ``diagnose=False`` leaves the convention checks out (an archive's saving)."""
    from ..ground.frame import misb_sensor
    from ..io.klv import KLVColumns, klv_telemetry, vmti_detections
    from ..io.klv.conventions import apply_to_telemetry
    from .diagnose import diagnose_frames, diagnose_vmti
    from .klvframes import (
        aircraft_features,
        check_frames,
        corner_footprint_features,
        corner_footprint_table,
        dem_footprint_features,
        explain_vmti,
        locate_vmti,
    )

    assume = tuple(dict.fromkeys(assume))
    if not len(stream):
        raise KLVError(f"{path}: no packet could be decoded, so there is nothing to locate",
                       [str(i) for i in stream.issues])
    columnar = isinstance(stream, KLVColumns)
    sensor = sensor or misb_sensor()
    carried = stream if carried is None else carried
    raw_tel = klv_telemetry(carried)
    if carried is not stream:  # (the carried state's rows left out)
        raw_tel = raw_tel.keep(raw_tel.line >= 0)
    tel = apply_to_telemetry(raw_tel, assume)
    ground = None if dem is None else OnDEM(dem)  # None: each packet's frame-centre elevation
    check = check_frames(tel, ground, sensor=sensor)
    from_0 = "vmti-pixels-from-0" in assume
    det = vmti_detections(carried, pixels_from=0 if from_0 else 1)
    table = None
    if dem is None and columnar:
        table, prints = corner_footprint_table(tel, check.geometry, every=footprint_every, first=first_footprint), []
    else:
        prints = (dem_footprint_features(tel, dem, sensor, every=footprint_every, first=first_footprint)
                  if dem is not None else corner_footprint_features(tel, check.geometry, every=footprint_every))
    layers = {"footprints": prints}
    if map_layers:
        layers |= {"aircraft": aircraft_features(tel),
                   "encoder footprints": corner_footprint_features(tel, None, every=footprint_every)}
    records = Records({})
    diagnoses = [diagnose_frames(raw_tel, sensor)] if diagnose else []
    v = None
    if len(det):
        v = locate_vmti(tel, det, ground, budget=budget, base=sensor)
        extra = {"stream": det.columns["stream"], **v.extra}
        records = fix_records(v.fixes, with_utc(extra, "unix"), v.uncertainty)  # ST 0601 time stamps are UNIX
        if map_layers:
            layers["fixes"] = fix_features(records)
        if diagnose and np.isfinite(det.columns["encoder_lat_deg"]).any():  # the encoder's locations: conventions
            def other_numbering():
                d = vmti_detections(carried, pixels_from=1 if from_0 else 0)
                return d, locate_vmti(tel, d, ground, base=sensor).fixes

            diagnoses += diagnose_vmti(det, v.fixes, other_numbering, assume=assume)
    notes = []
    if len(tel) and not footprint_drawn(prints, table):
        notes.append("no footprint could be drawn: " + (
            "the DEM is not under any frame" if dem is not None else
            "no packet gives the frame-centre elevation (tag 78, or 25 + geoid) that the corners stop at: give --dem"))
    if v is not None:
        why = explain_vmti(tel, det, v.fixes, ground)
        if why:
            notes.append(why)
    return KLVJob(Path(path), stream, tel, check, det, v, records, layers, dem, [*tel.issues, *det.issues],
                  diagnoses, assume, notes, table)


def telemetry_records(tel, time_origin="unix") -> Records:
    """telemetry.csv: every packet (or telemetry record) in eoloc's conventions; ``time_origin``
    as the config's [telemetry] time_origin (ST 0601 times are UNIX)."""
    utc = utc_times(tel.columns["time_s"], time_origin)
    return Records({"packet": np.asarray(tel.line), **({} if utc is None else {"time_utc": utc}),
                    **{k: np.asarray(v) for k, v in tel.columns.items() if k != "frame"}})


def frame_records(tel, check) -> Records:
    """frames.csv: eoloc's frame centre against the encoder's, per packet."""
    g, c = check.geometry, tel.columns
    return Records({"packet": np.asarray(tel.line), "stream": c["stream"], "time_s": c["time_s"],
                    "encoder_lat_deg": c["fc_lat_deg"],
                    "encoder_lon_deg": c["fc_lon_deg"], "encoder_h_m": c["fc_h_m"],
                    "eoloc_lat_deg": g.centre.lat_deg, "eoloc_lon_deg": g.centre.lon_deg, "eoloc_h_m": g.centre.h_m,
                    "centre_distance_m": check.centre_m, "range_difference_m": check.range_m,
                    **{f"corner{k + 1}_distance_m": check.corners_m[:, k] for k in range(4)}})


def frame_centre_records(tel, check, time_origin="unix") -> Records:
    """frame_centres: eoloc's frame centre of every packet as a point layer (lat_deg, lon_deg,
    h_m ellipsoidal), with the packet, its time and the distance to the encoder's centre."""
    g, c = check.geometry, tel.columns
    utc = utc_times(c["time_s"], time_origin)
    return Records({"packet": np.asarray(tel.line), "stream": c["stream"], "time_s": c["time_s"],
                    **({} if utc is None else {"time_utc": utc}),
                    "lat_deg": np.asarray(g.centre.lat_deg), "lon_deg": np.asarray(g.centre.lon_deg),
                    "h_m": np.asarray(g.centre.h_m), "status": STATUS_NAMES[np.asarray(g.centre.status, dtype=np.intp)],
                    "centre_distance_m": check.centre_m})


def write_klv_products(job: KLVJob, out: str | Path, *, formats=("csv", "geojson", "kml", "cot"),
                      grid=(), make_map: bool = True, tiles: str | None = None,
                      klv_out: str | Path | None = None, basemap=None, world: bool = True
                      ) -> tuple[list[Path], list[str]]:
    """telemetry.csv, frames.csv, conventions.csv, footprints, fixes (in ``formats``), eoloc.kml
    with every layer, map.html and, with ``klv_out``, the stream re-encoded with its fixes.
    Returns (paths, notes: no map drawn, packets written back without their fix)."""
    from ..io.kml import write_kml
    from ..io.mapview import drawable, write_map
    from ..io.writers import write_layer
    from ..util.extras import installed

    out = Path(out)
    written = [*write_layer(out, "telemetry", telemetry_records(job.telemetry), ["csv"]),
               *write_layer(out, "frames", frame_records(job.telemetry, job.check), ["csv"])]
    if job.diagnoses:
        from .diagnose import diagnosis_records

        written += write_layer(out, "conventions", diagnosis_records(job.diagnoses), ["csv"])
    prints = job.layers["footprints"]
    tables = [f for f in formats if f in ("geoparquet", "gpkg")]
    written += write_layer(out, "footprints", [f["properties"] for f in prints], ["geojson", *tables],
                           features=prints)
    from .klvframes import aircraft_features

    centres = frame_centre_records(job.telemetry, job.check)
    track = job.layers.get("aircraft") or aircraft_features(job.telemetry)
    written += write_layer(out, "frame_centres", centres, ["geojson", *tables])
    written += write_layer(out, "sensor_track", [f["properties"] for f in track], ["geojson", *tables],
                           features=track)
    if len(job.records):
        written += write_layer(out, "fixes", job.records, [f for f in formats if f != "kml"], grid=grid)
    notes = []
    if klv_out and job.vmti is not None and job.vmti.fixes.ok.any():
        path, unchanged = write_klv_stream(Path(klv_out), job)
        written.append(path)
        if unchanged:
            notes.append(f"--klv-out: {unchanged} packet(s) could not take their fix (a height outside tag 42's "
                         "range, -900 to 19 000 m, or a packet that cannot be read item by item): written as they "
                         "came, without it")
    elif klv_out:
        why = "no VMTI target was located" if len(job.records) else "the stream has no VMTI targets (ST 0903, tag 74)"
        notes.append(f"--klv-out: {why}, so there is no fix to write into tags 40-42: {klv_out} not written")
    kml_layers = {**job.layers, "frame centres": fix_features(centres)}
    for name in ("footprints", "encoder footprints"):  # ST 0601 times are UNIX: each outline its instant
        if name in kml_layers:
            feats = kml_layers[name]
            utc = utc_times([(f.get("properties") or {}).get("time_s", np.nan) for f in feats], "unix")
            kml_layers[name] = [{**f, "properties": {**(f.get("properties") or {}), "time_utc": t}}
                                for f, t in zip(feats, utc, strict=True)]
    written.append(write_kml(out / "eoloc.kml", kml_layers, name=job.path.name))
    lay = job.layers
    if make_map and not all(installed(m) for m in ("folium", "matplotlib")):
        notes.append("no map.html: the map needs folium and matplotlib, the report extra of eoloc (pip install "
                     "'eoloc[report]'); --no-map does without it")
    elif make_map and not drawable(lay["aircraft"], prints, lay["encoder footprints"], lay.get("fixes")):
        notes.append("no map: the stream has no aircraft position, footprint or fix to draw")
    elif make_map:
        written.append(write_map(out / "map.html", aircraft=lay["aircraft"], footprints=prints,
                                 encoder_footprints=lay["encoder footprints"], targets=lay.get("fixes"), dem=job.dem,
                                 tiles=tiles, title=f"eoloc: {job.path.name}", basemap=basemap, world=world,
                                 notes=notes))
    return written, notes


def write_klv_stream(path: Path, job: KLVJob) -> tuple[Path, int]:
    """The stream with each packet's first OK fix (lowest target id) in tags 40-42, 45, 46; and how
    many packets had to be passed on without theirs (:func:`eoloc.io.klv.encode.with_fix`: None)."""
    from ..io.klv.encode import with_fix

    v, tel = job.vmti, job.telemetry
    f = v.fixes
    first: dict[int, int] = {}
    for j in np.flatnonzero(f.ok):
        frame = int(v.extra["frame"][j])
        if frame not in first or v.extra["target_id"][j] < v.extra["target_id"][first[frame]]:
            first[frame] = j
    ce = v.uncertainty.get("ce90_m", np.full(len(f), np.nan))
    le = v.uncertainty.get("le90_m", np.full(len(f), np.nan))
    hae = tel.columns["target_elevation_hae"] > 0  # the datum the reader gives tag 42 in each packet
    out = bytearray()
    row_of = {int(k): i for i, k in enumerate(tel.line)}  # rows are grouped by stream, in time order
    unchanged = 0
    for p in job.stream.packets:
        raw = p.raw
        j = first.get(p.index) if p.standard == "ST 0601" else None
        if j is not None:
            new = with_fix(raw, f.lat_deg[j], f.lon_deg[j], f.h_m[j], ce90_m=ce[j], le90_m=le[j],
                           tag42_hae=bool(hae[row_of[p.index]]))
            unchanged += new is None  # a fix no tag can hold (height out of tag 42's range): passed on as it came
            raw = raw if new is None else new
        out += raw
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(bytes(out))
    return path, unchanged
