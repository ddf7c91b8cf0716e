"""The documentation site (issue 45, step 6): `mkdocs build --strict` with no warning (broken links
and anchors are warnings: strict turns them into failures), the tutorials' walk-throughs run as it
builds and what they wrote checked; every public name of `eoloc` has its
entry in the API reference, generated from its docstring; every command has its `--help` in the
command-line reference, the same text `eoloc COMMAND --help` prints; the pages, served on
loopback, open in headless Chromium offline without a script error, and the search finds; the
README, the site's home page, is what a newcomer reads first (at most 200 lines) and its links
into docs/ lead to pages that exist."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from where import ROOT

import eoloc

MKDOCS = Path(sys.executable).with_name("mkdocs")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site as `make docs` builds it: strict, the tutorials' walk-throughs run in ``walk``
    beside it (``EOLOC_DOCS_WALK``)."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "EOLOC_DOCS_WALK": str(out.parent / "walk")}
    done = subprocess.run([str(MKDOCS), "build", "--strict", "--site-dir", str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=2400, env=env)
    assert done.returncode == 0, done.stderr[-4000:]
    assert "WARNING" not in done.stderr, done.stderr
    return out


def test_the_tutorials_ran_as_written_when_the_site_was_built(site):
    """Every command of the four persona walk-throughs (docs/tutorials.md) ran in a shell exactly
    as written as the site was built (docs/hooks.py; a failing block would have stopped the
    build), the page says so under each block; then what they wrote is checked: the drone photo's
    laser fix against DJI's own target in its XMP (SOURCES.md: 22.5960255 N, 114.0066452 E), the
    HTTP answer, the live NDJSON, the report, the map."""
    import csv
    import json
    import math

    sys.path.insert(0, str(ROOT / "docs"))
    from hooks import walkthrough_blocks

    blocks = walkthrough_blocks((ROOT / "docs" / "tutorials.md").read_text(encoding="utf-8"))
    assert [b[0] for b in blocks] == ["Flight-test engineer", "FMV analyst", "Ground-station integrator",
                                      "Drone operator"]
    page = (site / "tutorials.html").read_text(encoding="utf-8")
    runs = re.findall(r"Run when this page was built \(\d{4}-\d\d-\d\d\): every command exited 0, (\d+) s, "
                      r"(\d+) files written", page)
    assert len(runs) == 4 and all(int(files) > 0 for _, files in runs), runs
    walk = site.parent / "walk" / "walk"
    with (walk / "photo" / "photo_fixes.csv").open(newline="", encoding="utf-8") as fh:
        (fix,) = list(csv.DictReader(fh))
    d_m = math.hypot((float(fix["lat_deg"]) - 22.5960255) * 110_760,
                     (float(fix["lon_deg"]) - 114.0066452) * 102_850)
    assert fix["status"] == "OK" and d_m < 0.3, d_m
    answer = json.loads((walk / "locate.json").read_text())["fixes"][0]
    assert answer["status"] == "OK" and 40.20 < answer["lat_deg"] < 40.31 and -105.70 < answer["lon_deg"] < -105.55
    features = [json.loads(line) for line in (walk / "live.ndjson").read_text().splitlines()]
    assert sum(f["properties"]["what"] == "target" for f in features) == 108
    assert (walk / "report" / "report.html").stat().st_size > 10_000
    assert (walk / "map" / "map.html").is_file() and (walk / "klv" / "eoloc.kml").is_file()
    assert (walk / "model" / "compensation.json").is_file() and (walk / "flight_with_fixes.klv").stat().st_size


def test_every_public_name_has_its_entry_in_the_api_reference(site):
    page = (site / "api.html").read_text(encoding="utf-8")
    ids = set(re.findall(r'id="(eoloc\.[\w.]+)"', page))
    names = [n for n in eoloc.__all__ if not n.startswith("__")]
    missing = [name for name in names if not any(i.endswith(f".{name}") for i in ids)]
    assert not missing, missing
    # and its docstring's first line with it (the reference is the docstrings, not a list of names)
    first = eoloc.OnDEM.__doc__.strip().splitlines()[0].split("``")[0].strip()[:40]
    assert first and first in re.sub(r"<[^>]+>", "", page)


def test_every_command_has_its_help_in_the_command_line_reference(site):
    import html

    from click.testing import CliRunner

    from eoloc.cli.main import main

    page = html.unescape(re.sub(r"<[^>]+>", "", (site / "cli.html").read_text(encoding="utf-8")))
    flat = " ".join(page.split())
    for name in main.list_commands(None):
        assert f"eoloc {name}" in page, name
        helped = CliRunner().invoke(main, [name, "--help"], terminal_width=100)
        assert helped.exit_code == 0
        options = re.findall(r"^\s+(--[a-z][\w-]+)", helped.output, re.M)
        assert options and all(o in flat for o in options), name  # every option the command has
        first = " ".join(helped.output.split("\n\n")[1].split())[:60]  # the help's first paragraph
        assert first in flat, (name, first)


def test_the_pages_open_in_a_browser_without_script_errors(site):
    """Served over HTTP on loopback (as `python -m http.server` or any static server serves it; its
    search runs in a web worker, which browsers do not start from file://), with no network beyond:
    every page of the site opens, titled, without a script error, and its search finds a name."""
    import functools
    import threading
    from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

    from browser import chromium

    class Quiet(SimpleHTTPRequestHandler):
        def log_message(self, *args) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Quiet, directory=str(site)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}/"
    from selenium.common.exceptions import TimeoutException
    from selenium.webdriver.support.ui import WebDriverWait

    d = chromium(offline=True)
    try:
        pages = sorted(p.name for p in site.glob("*.html") if p.name != "404.html")
        assert len(pages) >= 18
        for name in pages:
            d.get(base + name)
            try:  # the title, once the page has it (a loaded machine may hand it over a moment late)
                WebDriverWait(d, 30).until(lambda drv: drv.title.endswith("eoloc"))
            except TimeoutException:
                raise AssertionError((name, d.title)) from None
            assert d.find_element("css selector", "h1").text.strip(), name
            errors = [e for e in d.get_log("browser") if e["level"] == "SEVERE" and "favicon" not in e["message"]]
            assert not errors, (name, errors)
        d.get(base + "index.html")
        search = ("var q = document.getElementById('mkdocs-search-query'); if (!q) return null; q.value = 'OnDEM';"
                  "q.dispatchEvent(new Event('keyup'));"
                  "return Array.from(document.querySelectorAll('#mkdocs-search-results a')).map(a => a.href);")
        found = WebDriverWait(d, 60, poll_frequency=0.5).until(lambda drv: drv.execute_script(search))
        assert any("api.html" in h for h in found), found
    finally:
        d.quit()
        server.shutdown()


def test_the_readme_is_short_and_its_links_lead_somewhere():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    targets = re.findall(r"\]\(((?!https?:)[^)#]+)", text)
    assert len(targets) > 10
    for t in targets:
        assert (ROOT / t).is_file(), t


def test_a_walkthrough_that_fails_stops_the_build(tmp_path):
    """The hook's refusal: a block whose command fails (or prints a traceback) raises MkDocs's
    PluginError naming the persona and the error; a block that passes gets its line."""
    from mkdocs.exceptions import PluginError

    sys.path.insert(0, str(ROOT / "docs"))
    from hooks import run_walkthroughs

    page = "# T\n\n## Four ways in\n\n**Tester** — one:\n\n```sh\necho made > a.txt\n{}\n```\n\n## After\n"
    with pytest.raises(PluginError, match=r"the Tester walk-through failed \(exit 3\)(.|\n)*no such thing"):
        run_walkthroughs(page.format("echo no such thing >&2; exit 3"), tmp_path / "a")
    with pytest.raises(PluginError, match="Traceback"):
        run_walkthroughs(page.format("python3 -c 'raise SystemExit(\"Traceback (most recent call last)\")' || true"),
                         tmp_path / "b")
    done = run_walkthroughs(page.format("true"), tmp_path / "c")
    assert re.search(r"```\n\n\*Run when this page was built \(\d{4}-\d\d-\d\d\): every command exited 0, \d+ s, "
                     r"1 file written\.\*\n\n\n## After", done), done
    assert (tmp_path / "c" / "a.txt").read_text() == "made\n"
