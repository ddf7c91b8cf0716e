"""The `eoloc batch` job: many recordings, each an independent task, into one GeoParquet dataset
per layer.

A task is one file: a KLV stream (raw KLV or MPEG-TS: ``.klv``, ``.bin``, ``.ts``, ``.m2ts``,
``.mpg``, ``.mpeg``), a telemetry CSV with its detections beside it (``X_telemetry.csv`` +
``X_detections.csv``, or ``telemetry.csv`` + ``detections.csv`` in one folder) or a DJI ``.SRT``;
the file's content decides its reader (:mod:`eoloc.io.sources`). The task reads the
file itself (on whichever worker runs it: only its path and the settings travel), writes its
rows as one partition per layer, ``OUT/<layer>/file=<key>/part-0.parquet``, and returns a small
summary. Layers: ``fixes`` (located targets), ``packets`` (the aircraft, per packet/record),
``frames`` (eoloc's frame centre against the encoder's), ``footprints`` (polygons), ``issues``
(what was wrong with the file, line or packet by line or packet; no geometry).

Resumable: after its partitions are in place a task writes ``OUT/_manifest/<key>.json`` (the file's
size and modification time, the settings' fingerprint, its figures). A later run skips a file
whose manifest matches, redoes one that changed (its old partitions are removed first), and
retries the ones that failed; the partitions of files no longer among the inputs (renamed, moved,
deleted) are removed, so that the dataset holds each input once (``keep_missing`` keeps them).
One bad file never stops the batch: input errors end as ``failed`` with eoloc's message; anything
else (a bug) as ``bug`` with its traceback in ``OUT/_logs/<key>.txt``.
"""

from __future__ import annotations

import glob
import hashlib
import itertools
import json
import os
import shutil
import time
import traceback
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import EolocError, InputError
from ..io.geotable import ParquetLayer
from ..io.records import Coded, Records

KLV_SUFFIXES = (".klv", ".bin", ".ts", ".m2ts", ".mpg", ".mpeg")
LAYERS = ("fixes", "packets", "frames", "footprints", "issues")
MANIFEST = "_manifest"
LOGS = "_logs"
RANGE_BYTES = 256_000_000  # of a raw KLV file per task (some 10^6 packets: ~10 flight hours at 30 Hz)


@dataclass(frozen=True)
class BatchSettings:
    """What every task needs (pickled to the workers): the output folder and how to locate. Paths
    are made absolute: on a cluster the workers must see them (and the output folder) at the
    same place, a shared file system."""

    out_dir: str
    dem_paths: tuple[str, ...] = ()
    vertical: str = "egm96"
    geoid: str | None = None
    dem_crs: str | None = None
    config_path: str | None = None
    rule_values: tuple[tuple[str, float | str], ...] = ()  # the stop rule of telemetry CSVs (rules.spec keys)
    footprint_every: int = 1
    grid: tuple[str, ...] = ()
    strict: bool = False
    assume: tuple[str, ...] = ()
    segment_bytes: int | None = None  # a KLV file's bytes read at a time (None: eoloc.io.klv.segments.SEGMENT_BYTES)
    range_bytes: int = RANGE_BYTES  # a raw KLV file longer than this is cut in byte ranges, a task each (0: never)

    def __post_init__(self) -> None:
        def absolute(p: str | None) -> str | None:
            return None if p is None else os.path.abspath(p)

        object.__setattr__(self, "out_dir", absolute(self.out_dir))
        object.__setattr__(self, "dem_paths", tuple(absolute(p) for p in self.dem_paths))
        object.__setattr__(self, "geoid", absolute(self.geoid))
        object.__setattr__(self, "config_path", absolute(self.config_path))

    def fingerprint(self) -> str:
        """What the results depend on besides the file: every setting but the folder, the DEM and
        config files' sizes and times, and eoloc's version."""
        from .. import __version__

        def stamp(p: str | None) -> list:
            if p is None:
                return []
            s = os.stat(p)
            return [os.path.abspath(p), s.st_size, s.st_mtime_ns]

        d = {k: v for k, v in asdict(self).items() if k != "out_dir"}
        d["files"] = [stamp(p) for p in (*self.dem_paths, self.geoid, self.config_path)]
        d["eoloc"] = __version__
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Task:
    """One input: ``path`` (the KLV stream or the telemetry CSV), its detections CSV or None,
    and ``key``, the name of its partitions."""

    path: str
    detections: str | None
    key: str
    span: tuple[int, int] | None = None  # a byte range of a raw KLV file (the file's other ranges: other tasks)
    part: int = 0  # the range's number in the file
    start: Any = field(default=None, compare=False)  # what the bytes before the range leave (.klv.RangeStart)

    @property
    def kind(self) -> str:
        """"klv" for a KLV stream (found as one by its name, or one by its content: its reader says what
        is wrong with a .klv that is not), else "telemetry" (any other telemetry source)."""
        from ..io.sources import identify

        if self.path.lower().endswith(KLV_SUFFIXES):
            return "klv"
        return "klv" if identify(self.path).name == "klv" else "telemetry"


@dataclass
class FileResult:
    """One task's outcome: done, skipped (already done), failed (bad input) or bug."""

    key: str
    path: str
    status: str
    packets: int = 0
    fixes: int = 0
    fixes_ok: int = 0
    issues: int = 0
    seconds: float = 0.0
    message: str = ""

    def row(self) -> dict:
        return asdict(self)


@dataclass
class BatchJob:
    results: list[FileResult]
    out_dir: Path
    notes: list[str] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for r in self.results:
            out[r.status] = out.get(r.status, 0) + 1
        return out


def task_key(path: str | Path) -> str:
    """A partition name that is readable and unique: the file's stem and a hash of its full path."""
    p = Path(path).resolve()
    stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in p.stem)[:60]
    return f"{stem}-{hashlib.sha1(str(p).encode()).hexdigest()[:8]}"


def find_tasks(patterns: Sequence[str]) -> list[Task]:
    """The tasks of ``patterns``: files, folders (searched recursively) and glob patterns (``**``
    allowed). KLV streams by suffix; a telemetry CSV (name containing ``telemetry``) with its
    detections CSV (the same name with ``detections``) if there is one. A pattern that matches
    no input is an InputError naming it."""
    found: dict[str, Task] = {}
    empty = []
    for pattern in patterns:
        paths = [Path(p) for p in sorted(glob.glob(pattern, recursive=True))] or (
            [Path(pattern)] if Path(pattern).exists() else [])
        files = []
        for p in paths:
            files += sorted(x for x in p.rglob("*") if x.is_file()) if p.is_dir() else [p]
        n = len(found)
        for f in files:
            name = f.name.lower()
            f = f.resolve()  # absolute: a worker on another machine has another working directory
            if name.endswith(KLV_SUFFIXES):
                found.setdefault(str(f), Task(str(f), None, task_key(f)))
            elif name.endswith(".srt") or (name.endswith(".csv") and "telemetry" in name):
                det = f.with_name(f.name.replace("telemetry", "detections").replace("Telemetry", "Detections"))
                found.setdefault(str(f), Task(str(f), str(det) if det.is_file() else None, task_key(f)))
        if len(found) == n:
            empty.append(pattern)
    if empty:
        raise InputError(f"no KLV stream ({', '.join(KLV_SUFFIXES)}), telemetry CSV (*telemetry*.csv) or DJI .SRT "
                         "found in " + ", ".join(repr(p) for p in empty))
    return sorted(found.values(), key=lambda t: t.path)


# -- one task ------------------------------------------------------------------------------------

@cache
def _dem(paths: tuple[str, ...], vertical: str, geoid: str | None, dem_crs: str | None):
    """The DEM, opened once per worker process."""
    if not paths:
        return None
    from ..terrain import open_dem

    return open_dem(list(paths), vertical=vertical, geoid=geoid, assume_crs=dem_crs)


@cache
def _config(path: str | None):
    if path is None:
        return None
    from ..io.config import load_config

    return load_config(path)


def _stamp(path: str) -> dict:
    s = os.stat(path)
    return {"size": s.st_size, "mtime_ns": s.st_mtime_ns}


def manifest_path(out_dir: str | Path, key: str) -> Path:
    return Path(out_dir) / MANIFEST / f"{key}.json"


def is_done(task: Task, settings: BatchSettings, fingerprint: str) -> FileResult | None:
    """The recorded result when ``task`` was done with these settings and its files have not changed."""
    p = manifest_path(settings.out_dir, task.key)
    try:
        m = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    inputs = {q: _stamp(q) for q in (task.path, task.detections) if q}
    if m.get("fingerprint") != fingerprint or m.get("inputs") != inputs or m.get("result", {}).get("status") != "done":
        return None
    return FileResult(**{**m["result"], "status": "skipped"})


def _layers_klv(task: Task, settings: BatchSettings) -> Iterator[tuple[dict[str, tuple[Records, Any]], int]]:
    """The layers of a KLV file a segment at a time (:func:`.klv.klv_segment_jobs`), with the
    segment's packet count."""
    from .klv import frame_records, klv_segment_jobs, telemetry_records
    from .setup import misb_setup

    sensor, budget = misb_setup(_config(settings.config_path))
    dem = _dem(settings.dem_paths, settings.vertical, settings.geoid, settings.dem_crs)
    for seg, job in klv_segment_jobs(task.path, segment_bytes=settings.segment_bytes, dem=dem, sensor=sensor,
                                     budget=budget, footprint_every=settings.footprint_every,
                                     strict=settings.strict, assume=settings.assume, span=task.span,
                                     start=task.start):
        if job is None:
            yield {"issues": (_issue_records([str(i) for i in seg.issues]), None)}, 0
            continue
        frames = frame_records(job.telemetry, job.check).columns
        frames = {"lat_deg": frames.pop("eoloc_lat_deg"), "lon_deg": frames.pop("eoloc_lon_deg"),
                  "h_m": frames.pop("eoloc_h_m"), **frames}
        prints = job.layers["footprints"]
        footprints = job.footprint_table or (Records.from_rows([f["properties"] for f in prints]), prints)
        issues = [str(i) for i in [*seg.issues, *job.issues]]
        yield {"fixes": (job.records, None), "packets": (telemetry_records(job.telemetry), None),
               "frames": (Records(frames), None), "footprints": footprints,
               "issues": (_issue_records(issues), None)}, len(job.telemetry)


def _layers_csv(task: Task, settings: BatchSettings) -> Iterator[tuple[dict[str, tuple[Records, Any]], int]]:
    """The layers of a telemetry CSV (and its detections), read whole."""
    from ..rules.spec import SPECS, rule_from_values
    from .klv import telemetry_records
    from .locate import locate_files

    cfg = _config(settings.config_path)
    if cfg is None:
        raise InputError(f"{task.path}: a telemetry CSV needs --config (the camera) to be located")
    dem = _dem(settings.dem_paths, settings.vertical, settings.geoid, settings.dem_crs)
    try:
        rule = rule_from_values({**dict(settings.rule_values), "dem": dem})
    except InputError:
        flags = " or ".join(f"{s.flag} {s.metavar}" for s in SPECS)
        raise InputError(f"{task.path}: a telemetry CSV needs one stop rule: {flags}") from None
    job = locate_files(cfg, task.path, task.detections, rule)
    yield {"fixes": (job.records, None),
           "packets": (telemetry_records(job.telemetry, cfg.telemetry.time_origin), None),
           "issues": (_issue_records([*map(str, job.issues), *job.notes]), None)}, len(job.telemetry)


def _issue_records(messages: list[str]) -> Records:
    return Records({"message": np.array(messages, dtype=object)})


def _partition_records(records: Records, source: str, grid: tuple[str, ...]) -> Records:
    from ..io.gridref import with_grid_columns

    n = len(records)
    cols = {"source_file": np.full(n, source, dtype=object), **records.columns}
    coded = {**records.coded, "source_file": Coded(np.zeros(n, np.int8), np.array([source], dtype=object))}
    return with_grid_columns(Records(cols, coded), grid)


def remove_partitions(out_dir: Path, key: str) -> None:
    for layer in LAYERS:
        shutil.rmtree(out_dir / layer / f"file={key}", ignore_errors=True)


def process_file(task: Task, settings: BatchSettings, fingerprint: str) -> FileResult:
    """Run one task where it is called (a worker): read, locate, write the partitions and the
    manifest; never raises for the file's sake. A byte range of a file (``task.span``) writes its
    own files in the file's partitions (``range-NNNNN-part-0.parquet``), and leaves the file's
    partitions and manifest to the batch (:func:`batch_job`: its other ranges)."""
    out_dir = Path(settings.out_dir)
    t0 = time.perf_counter()
    result = FileResult(task.key, task.path, "done")
    writers: dict[str, ParquetLayer] = {}
    ranged = task.span is not None
    stem = f"range-{task.part:05d}-part" if ranged else "part"
    try:
        inputs = {q: _stamp(q) for q in (task.path, task.detections) if q}
        if not ranged:
            remove_partitions(out_dir, task.key)
        writers.update({layer: ParquetLayer(out_dir / layer / f"file={task.key}", stem=stem) for layer in LAYERS})
        for layers, n in (_layers_klv if task.kind == "klv" else _layers_csv)(task, settings):
            for layer, (records, features) in layers.items():
                writers[layer].write(_partition_records(records, task.path, settings.grid), features)
            fixes = layers.get("fixes", (Records({}), None))[0]
            result.packets, result.fixes = result.packets + n, result.fixes + len(fixes)
            result.fixes_ok += int(np.sum(fixes["status"] == "OK")) if len(fixes) else 0
            result.issues += len(layers["issues"][0])
        for w in writers.values():
            w.close()
    except EolocError as exc:
        result.status, result.message = "failed", str(exc)
        inputs = None
    except OSError as exc:  # unreadable (permissions, a file that vanished, a full disk)
        result.status, result.message = "failed", f"{exc.filename or task.path}: {exc.strerror or exc}"
        inputs = None
    except Exception as exc:  # a bug: the batch goes on, the traceback is kept for the report
        result.status = "bug"
        log = out_dir / LOGS / f"{task.key}.txt"
        log.parent.mkdir(parents=True, exist_ok=True)
        log.write_text(f"{task.path}\n{traceback.format_exc()}", encoding="utf-8")
        result.message = f"{type(exc).__name__}: {exc} (traceback in {log})"
        inputs = None
    result.seconds = round(time.perf_counter() - t0, 3)
    if inputs is None:  # (no partial partitions: a failed file has none)
        for w in writers.values():
            w.abort()
        if not ranged:
            remove_partitions(out_dir, task.key)
        result.packets = result.fixes = result.fixes_ok = result.issues = 0
    elif not ranged:
        write_manifest(out_dir, task, inputs, fingerprint, result)
    return result


def write_manifest(out_dir: Path, task: Task, inputs: dict, fingerprint: str, result: FileResult) -> None:
    m = manifest_path(out_dir, task.key)
    m.parent.mkdir(parents=True, exist_ok=True)
    tmp = m.with_suffix(".tmp")
    tmp.write_text(json.dumps({"path": task.path, "inputs": inputs, "fingerprint": fingerprint,
                               "result": result.row()}, indent=1), encoding="utf-8")
    os.replace(tmp, m)


# -- a large file in byte ranges -----------------------------------------------------------------

def file_spans(task: Task, range_bytes: int) -> list[tuple[int, int]] | None:
    """The byte ranges of a raw KLV file longer than ``range_bytes`` (each begun where the reader
    stands at a packet start: :func:`eoloc.io.klv.segments.range_cut`), or None: a file read as one
    task (shorter, an MPEG-TS, a telemetry CSV, unreadable: its task says why)."""
    from ..io.klv.reader import looks_like_ts
    from ..io.klv.segments import range_cut

    if range_bytes <= 0 or task.detections is not None or not task.path.lower().endswith(KLV_SUFFIXES):
        return None
    try:
        size = os.stat(task.path).st_size
        if size <= range_bytes:
            return None
        with open(task.path, "rb") as f:
            if looks_like_ts(f.read(5 * 188)):
                return None
            cuts = [0, *(range_cut(f, k * range_bytes) for k in range(1, -(-size // range_bytes))), size]
    except OSError:
        return None
    return list(itertools.pairwise(cuts))


def summarize_range(task: Task, settings: BatchSettings) -> tuple | str:
    """:func:`.klv.range_summary` of a range task where it is called (a worker), or why not (the
    batch then runs the file as one task, which says it again: eoloc's message, or a bug's
    traceback)."""
    from .klv import range_summary

    try:
        return range_summary(task.path, task.span, segment_bytes=settings.segment_bytes, strict=settings.strict)
    except Exception as exc:  # (any: the file's own task reports it as it would without ranges)
        return f"{type(exc).__name__}: {exc}"


def ranged_tasks(tasks: list[Task], settings: BatchSettings, mapper) -> tuple[list[Task], dict[str, list[Task]]]:
    """``tasks`` with each raw KLV file longer than ``settings.range_bytes`` replaced by a task per
    byte range, each given what the ranges before it leave (:class:`.klv.RangeStart`, from every
    range read on its own first, through ``mapper``); and those files' range tasks by key. A file
    whose ranges cannot all be read, or hold no good packet, stays one task (its reading says
    why)."""
    from .klv import range_starts

    spans = {t.key: file_spans(t, settings.range_bytes) for t in tasks}
    pieces = [replace(t, span=sp, part=k) for t in tasks for k, sp in enumerate(spans[t.key] or [])]
    summaries = mapper(summarize_range, [(p, settings) for p in pieces]) if pieces else []
    by_key: dict[str, list] = {}
    for p, s in zip(pieces, summaries, strict=True):
        by_key.setdefault(p.key, []).append((p, s))
    out, ranges = [], {}
    for t in tasks:
        got = by_key.get(t.key)
        if not got or any(isinstance(s, str) for _, s in got) or not sum(s[1] for _, s in got):
            out.append(t)
            continue
        starts = range_starts([s for _, s in got])
        ranges[t.key] = [replace(p, start=st) for (p, _), st in zip(got, starts, strict=True)]
        out += ranges[t.key]
    return out, ranges


def file_result(task: Task, parts: list[FileResult], settings: BatchSettings, fingerprint: str) -> FileResult:
    """One file's result from its ranges' (in order): done when each is, with their counts summed
    and its manifest written; else the first range's failure, and the file's partitions removed."""
    out_dir = Path(settings.out_dir)
    bad = next((r for r in parts if r.status != "done"), None)
    result = FileResult(task.key, task.path, "done", seconds=round(sum(r.seconds for r in parts), 3))
    if bad is not None:
        remove_partitions(out_dir, task.key)
        result.status, result.message = bad.status, bad.message
        return result
    for r in parts:
        result.packets, result.fixes = result.packets + r.packets, result.fixes + r.fixes
        result.fixes_ok, result.issues = result.fixes_ok + r.fixes_ok, result.issues + r.issues
    try:
        inputs = {task.path: _stamp(task.path)}
    except OSError as exc:
        remove_partitions(out_dir, task.key)
        result.status, result.message = "failed", f"{task.path}: {exc.strerror or exc}"
        return result
    write_manifest(out_dir, task, inputs, fingerprint, result)
    return result


# -- the batch -----------------------------------------------------------------------------------

def stale_keys(out_dir: Path, keys: set[str]) -> dict[str, str]:
    """The partitions' keys in ``out_dir`` (in any layer, or in a manifest) that are not ``keys``,
    each with the file it was made from (as its manifest says; the key where there is none)."""
    found = {p.stem for p in (out_dir / MANIFEST).glob("*.json")}
    for layer in LAYERS:
        found |= {p.name.removeprefix("file=") for p in (out_dir / layer).glob("file=*") if p.is_dir()}
    stale = {}
    for key in sorted(found - keys):
        try:
            stale[key] = json.loads(manifest_path(out_dir, key).read_text(encoding="utf-8"))["path"]
        except (OSError, ValueError, KeyError):
            stale[key] = key
    return stale


def prune(out_dir: Path, keys: set[str]) -> list[str]:
    """Remove the partitions, manifests and logs of every key in ``out_dir`` but ``keys`` (files no
    longer among the inputs: renamed, moved, deleted): the files they came from."""
    gone = stale_keys(out_dir, keys)
    for key in gone:
        remove_partitions(out_dir, key)
        manifest_path(out_dir, key).unlink(missing_ok=True)
        (out_dir / LOGS / f"{key}.txt").unlink(missing_ok=True)
    return list(gone.values())


def batch_job(patterns: Sequence[str] | Iterable[Task], settings: BatchSettings, *, mapper=None, redo: bool = False,
              keep_missing: bool = False, on_done: Callable[..., None] | None = None) -> BatchJob:
    """Every task of ``patterns`` (or the given tasks) through ``mapper`` (:mod:`eoloc.accuracy.runners`:
    here by default, or a Dask cluster); ``redo`` ignores the manifests. The dataset then holds the
    files of this run and no others: the partitions of files no longer among the inputs (renamed,
    moved, deleted) are removed, unless ``keep_missing``. ``on_done()`` after each file, skipped
    ones included, and ``on_done(1 / k)`` after each of a file's ``k`` byte ranges (progress: the
    calls add up to the number of files)."""
    from ..accuracy.runners import local_map

    patterns = list(patterns)
    tasks = patterns if patterns and isinstance(patterns[0], Task) else find_tasks(patterns)
    out_dir = Path(settings.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fingerprint = settings.fingerprint()
    results: dict[str, FileResult] = {}
    todo = []
    for t in tasks:
        done = None if redo else is_done(t, settings, fingerprint)
        if done is not None:
            results[t.key] = done
            if on_done is not None:
                on_done()
        else:
            todo.append(t)
    run = mapper or local_map
    pieces, ranges = ranged_tasks(todo, settings, run)
    for key in ranges:  # (the ranges write their own files into the file's partitions)
        remove_partitions(out_dir, key)
    def finished(i: int) -> None:
        if on_done is not None:
            key = pieces[i].key
            on_done() if key not in ranges else on_done(1.0 / len(ranges[key]))

    done_parts: dict[str, list[FileResult]] = {}
    for task, r in zip(pieces, run(process_file, [(t, settings, fingerprint) for t in pieces], finished),
                       strict=True):
        if task.span is None:
            results[r.key] = r
        else:
            done_parts.setdefault(task.key, []).append(r)
    for t in todo:
        if t.key in ranges:
            results[t.key] = file_result(t, done_parts[t.key], settings, fingerprint)
    ordered = [results[t.key] for t in tasks]
    notes = []
    if not keep_missing:
        gone = prune(out_dir, {t.key for t in tasks})
        if gone:
            notes.append(f"removed the partitions of {len(gone)} file(s) no longer among the inputs ("
                         + ", ".join(gone[:5]) + (", ..." if len(gone) > 5 else "") + "; --keep-missing keeps them)")
    if any(r.status == "skipped" for r in ordered):
        notes.append(f"{sum(r.status == 'skipped' for r in ordered)} file(s) already done with these settings were "
                     "skipped (--redo to do them again)")
    return BatchJob(ordered, out_dir, notes)


def status_records(job: BatchJob) -> Records:
    return Records.from_rows([r.row() for r in job.results])
