"""The documentation site (issue 45, step 6): `mkdocs build --strict` with no warning (broken links
and anchors are warnings: strict turns them into failures); every public name of `eoloc` has its
entry in the API reference, generated from its docstring; every command has its `--help` in the
command-line reference, the same text `eoloc COMMAND --help` prints; the pages, served on
loopback, open in headless Chromium offline without a script error, and the search finds; the
README, the site's home page, is what a newcomer reads first (at most 200 lines) and its links
into docs/ lead to pages that exist."""

from __future__ import annotations

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
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([str(MKDOCS), "build", "--strict", "--site-dir", str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-4000:]
    assert "WARNING" not in done.stderr, done.stderr
    return out


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
        search = ("var q = document.getElementById('mkdocs-search-query'); q.value = 'OnDEM';"
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
