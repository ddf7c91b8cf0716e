"""`eoloc batch`: an archive of recordings into one GeoParquet dataset per layer, here or on Dask."""

from __future__ import annotations

import sys

import click

from .common import progress
from .main import console, err_console, warn
from .options import config_option, dask_option, grid_option, out_option, rule_options

BATCH_HELP = """Process many recordings, each file an independent task, into one GeoParquet dataset per layer.

\b
eoloc batch PATTERN... --out DIR [--dem F] [--config C] [--dask ADDRESS | --dask local:N]
  PATTERN: files, folders (searched recursively) or globs ('flights/**/*.ts'; quote them).
  Inputs: KLV streams (.klv .bin .ts .m2ts .mpg .mpeg; raw KLV or MPEG-TS), located as
  `eoloc klv` does (VMTI targets on --dem, else on each packet's frame-centre elevation); and
  telemetry CSVs (*telemetry*.csv, with the *detections*.csv of the same name beside them, or
  the image centres without one) and DJI .SRT files, located as `eoloc locate` does (needs
  --config and --target-height H or --dem). The file's content decides how it is read.
  Output, under DIR, one GeoParquet dataset per layer (hive-partitioned by file):
    fixes/       located targets (Point Z: lon, lat, ellipsoidal height; EPSG:4979)
    packets/     the aircraft per packet or telemetry record
    frames/      eoloc's frame centre per packet, with its distance to the encoder's
    footprints/  the frame outlines (polygons)
    issues/      what was wrong with each file (packet or line, and why)
  plus batch_status.csv (one row per file). Read a layer with geopandas.read_parquet('DIR/fixes')
  or DuckDB: SELECT * FROM read_parquet('DIR/fixes/*/*.parquet', hive_partitioning = true).
  A KLV file is read and written a segment at a time (--segment-mb of KLV: memory stays
  bounded whatever the file's size; each layer's file holds one row group per segment, with the
  same rows as one reading; an MPEG-TS has its transport read 8 segments at a time, its KLV set
  aside in temporary files (TMPDIR), then read PID by PID); a CSV is read whole. A raw KLV file
  longer than --range-mb is cut in byte ranges at packet boundaries, a task each, so that the
  workers share a long recording (range-NNNNN-part-0.parquet files in its partitions; the
  same rows as one reading).
  Resumable: files already done with the same settings are skipped; a changed file is redone;
  --redo does everything again. One bad file never stops the batch: it is listed as failed with
  the reason (exit code 2 at the end); a bug in eoloc is listed with its traceback in DIR/_logs.
  Workers read the files themselves: only paths and small summaries go through Dask, so on a
  cluster the inputs, DEM, config and DIR must be on a file system every worker sees at the
  same path.
"""


@click.command(help=BATCH_HELP)
@click.argument("patterns", nargs=-1, required=True)
@out_option("the datasets")
@rule_options(dem_help="DEM file(s) (repeat for tiles): the terrain of every file (KLV: the targets' ground; default: "
                        "each packet's frame-centre elevation). Telemetry CSVs take one stop rule; KLV the DEM only.")
@config_option(required=False, help_text="TOML: the camera (needed for telemetry CSVs), [installation] and "
                                         "[accuracy.budget] (uncertainty columns).")
@grid_option()
@click.option("--footprint-every", type=click.IntRange(1), default=1, show_default=True,
              help="KLV: one footprint every N packets.")
@click.option("--strict", is_flag=True, help="KLV: drop packets that break MISB ST 0601 as written.")
@click.option("--segment-mb", "segment_mb", type=click.FloatRange(0.001), default=1.0, show_default=True,
              metavar="MB", help="KLV: megabytes (10^6 bytes) of a file's KLV read, located and written at a time "
                                 "(about 5 000 packets with 5 VMTI targets; a worker's memory grows by some 40 MB "
                                 "per MB; an MPEG-TS's transport is read 8 times as much, at least 8 MB, at a "
                                 "time).")
@click.option("--range-mb", "range_mb", type=click.FloatRange(0), default=256.0, show_default=True, metavar="MB",
              help="Raw KLV: a file longer than this many megabytes is cut in byte ranges of about this size, a task "
                   "each (every range is first read for its packet count and what a receiver knows at its end, then "
                   "located from what the ranges before it leave); 0: every file one task.")
@click.option("--redo", is_flag=True, help="Do every file again, even those already done.")
@click.option("--keep-missing", is_flag=True, help="Keep the partitions of files that were in an earlier run into "
                                                    "--out but are not among the inputs now (default: removed, so "
                                                    "that the dataset holds each input file once).")
@dask_option
def batch(patterns, out_dir, rule_values, dem_paths, vertical, geoid, dem_crs, config_path, grid,
          footprint_every, strict, segment_mb, range_mb, redo, keep_missing, dask_address) -> None:
    from ..io.writers import write_layer
    from ..jobs.accuracy import mapper
    from ..jobs.batch import BatchSettings, batch_job, find_tasks, status_records
    from .render import batch_table

    settings = BatchSettings(out_dir, tuple(dem_paths), vertical, geoid, dem_crs, config_path,
                             tuple((k, v) for k, v in rule_values.items() if v is not None), footprint_every,
                             tuple(grid), strict, segment_bytes=int(segment_mb * 1e6),
                             range_bytes=int(range_mb * 1e6))
    tasks = find_tasks(patterns)
    if dem_paths:  # open it once here, so that a DEM that cannot be read is one message, not one per file
        from .common import open_dem

        open_dem(dem_paths, vertical, geoid, dem_crs)
    if config_path:
        from .common import load_config

        load_config(config_path)
    with mapper(dask_address) as m, progress() as bar:
        task = bar.add_task(f"{len(tasks)} files", total=len(tasks))
        job = batch_job(tasks, settings, mapper=m, redo=redo, keep_missing=keep_missing,
                        on_done=lambda part=1.0: bar.advance(task, part))  # (a byte range: its part of a file)
    console.print(batch_table(job))
    for note in job.notes:
        warn(note, "note")
    written = write_layer(job.out_dir, "batch_status", status_records(job), ["csv"])
    err_console.print("wrote " + ", ".join(str(p) for p in written) + f" and the datasets under {job.out_dir}")
    counts = job.counts()
    if counts.get("bug"):
        err_console.print(f"[bold red]{counts['bug']} file(s) hit a bug in eoloc[/]: the traceback of each is in "
                          f"{job.out_dir / '_logs'}; please report it")
        sys.exit(1)
    if counts.get("failed"):
        sys.exit(2)
