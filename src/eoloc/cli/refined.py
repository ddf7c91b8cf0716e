"""``--refine`` of the commands that locate (video, photo, klv, locate): `eoloc refine` run first,
with its defaults, into OUT/refine/; the command then goes on with what it wrote."""

from __future__ import annotations

from pathlib import Path

import click

from .common import load_config, working
from .main import err_console, report_issues, warn

ALL_PRIORS = ("mount", "boresight", "heading", "time", "position", "frame")  # eoloc refine's default: the budget's


def refine_video_first(video, telemetry, config_path, dem, out: Path, *,
                       max_gap_s: float = 0.5) -> tuple[Path, Path | None, Path | None]:
    """The video, telemetry and config to go on with after refining ``video`` into ``out``: the
    refined CSV and config (``telemetry`` given), or, for a video with its own KLV, the video with
    every packet's pose corrected (NAME_refined.ts) and no telemetry; its config, with a config
    given, NAME_refined.toml (the installation zero: the sensor angles carry it; the refined
    budget), else none."""
    from ..jobs.refine import refine_video

    need_dem(dem)
    if telemetry is None and not looks_like_video(video):
        raise click.UsageError(f"--refine needs the video the KLV came with: {video} is not a video (raw KLV has no "
                               "pixels to refine from; give the MPEG-TS, or mux the KLV into its video: eoloc mux)")
    cfg = load_config(config_path) if config_path else None
    with working("refining the telemetry from the pixels..."):
        job = refine_video(video, telemetry, cfg, dem, config_path=config_path, out=out, max_gap_s=max_gap_s,
                           priors_from_budget=ALL_PRIORS)
    report_issues(job.issues)
    say_refined(job.refinement, out)
    if telemetry is not None:
        return Path(video), out / "telemetry_refined.csv", out / "config_refined.toml"
    stem = Path(video).stem
    return out / f"{stem}_refined.ts", None, (out / f"{stem}_refined.toml" if config_path else None)


def refine_photos_first(photos, dem, out: Path, config_path=None) -> tuple[dict, Path, Path | None]:
    """The photos' poses refined (into ``out``) by file name, the file they were written to, and the
    config to go on with: with a config that has an [accuracy.budget], the refined one
    (config_refined.toml: what refinement left unknown), else the config as given."""
    from ..jobs.refine import refine_photos
    from ..jobs.setup import optional_budget

    need_dem(dem)
    budget = optional_budget(load_config(config_path) if config_path else None)
    with working("refining the photos' poses from their overlap..."):
        job = refine_photos(photos, dem, out=out, budget=budget, config_path=config_path,
                            priors_from_budget=ALL_PRIORS)
    for w in job.failed:
        warn(w)
    say_refined(job.refinement, out)
    config = out / "config_refined.toml" if job.budget and config_path else config_path
    return {Path(row["file"]).name: row for row in job.rows}, out / "photos_refined.csv", config


def looks_like_video(path) -> bool:
    """A video container by its first bytes: MPEG-TS (sync bytes 188 apart), MP4/MOV ("ftyp"),
    Matroska/WebM (EBML). Raw KLV (its key 06 0E 2B 34), photos and text are not."""
    try:
        with open(path, "rb") as f:
            head = f.read(189)
    except OSError:
        return False
    ts = head[:1] == b"\x47" and (len(head) < 189 or head[188:189] == b"\x47")
    return ts or head[4:8] == b"ftyp" or head[:4] == b"\x1aE\xdf\xa3"


def need_dem(dem) -> None:
    from ..terrain import DEM

    if not isinstance(dem, DEM):
        raise click.UsageError("--refine needs the terrain: --dem FILE (the tie points' heights are held to it)")


def say_refined(refinement, out: Path) -> None:
    """What a refinement run first found: its warnings, then one line of estimates +- 1-sigma and
    where its files went."""
    for w in refinement.warnings:
        warn(w)
    r = refinement
    err_console.print("refined: " + ", ".join(f"{n} {v:+.4g} ± {sg:.2g}" for n, v, sg in
                                              zip(r.names, r.values, r.sigma, strict=True)) + f" (wrote {out})",
                      highlight=False)
