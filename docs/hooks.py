"""MkDocs hooks of eoloc's documentation site: the command-line reference written from the
commands' own ``--help`` (click, in this process: what a user sees, never a copy that drifts), the
tutorials' walk-throughs executed as the site builds (with ``EOLOC_DOCS_WALK`` set to a folder:
`make docs` and `make test` set it; a block that fails stops the build, each block's page says
what its run did), and the papers' citation marks ([S13], [Z15], [Q], [P]) kept as text rather
than read as links."""

from __future__ import annotations

import os
import re
from pathlib import Path

MARK = "<!-- eoloc commands -->"
README = "<!-- eoloc readme -->"
CITATION = re.compile(r"(?<![\\\w])\[([A-Z][A-Za-z0-9]{0,4})\](?![(\[:])")
ROOT = Path(__file__).resolve().parents[1]
WALK = "EOLOC_DOCS_WALK"  # the folder the tutorials run in; unset: the page as written, nothing run
# a persona's walk-through: its bold name, then its shell block
BLOCK = re.compile(r"(\*\*([^*]+)\*\*[^`]*?```sh\n(.*?)```)", re.S)


def walkthrough_section(text: str) -> tuple[int, int]:
    """Where the persona walk-throughs of docs/tutorials.md are: its "Four ways in" section."""
    start = text.index("## Four ways in")
    end = text.find("\n## ", start + 10)
    return start, end if end >= 0 else len(text)


def walkthrough_blocks(text: str) -> list[tuple[str, str]]:
    """The walk-throughs of docs/tutorials.md's text: (persona, shell block) in order."""
    start, end = walkthrough_section(text)
    return [(m.group(2), m.group(3)) for m in BLOCK.finditer(text[start:end])]


def run_block(block: str, where: Path) -> tuple[int, float, str]:
    """One walk-through block run in a shell exactly as written (``bash -e -o pipefail``) from
    ``where``, a folder with the repository's src/ and tests/ as the root has them, this Python's
    environment first on the PATH: (exit status, seconds, its stderr). Whatever the block started
    and left running (a server) is stopped with it."""
    import contextlib
    import signal
    import subprocess
    import sys
    import time

    for name in ("src", "tests"):
        if not (where / name).exists():
            (where / name).symlink_to(ROOT / name)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    env.pop("COLUMNS", None)
    t0 = time.perf_counter()
    proc = subprocess.Popen(["bash", "-e", "-o", "pipefail", "-c", block], cwd=where, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _, err = proc.communicate(timeout=900)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)  # a server the block started and did not stop
    return proc.returncode, time.perf_counter() - t0, err


def run_walkthroughs(markdown: str, where: Path) -> str:
    """Every walk-through block of the tutorials page run in ``where`` (in order: later blocks read
    what earlier ones wrote); the page with a line under each block saying what its run did. A
    block that fails (or prints a traceback) stops the build, naming the persona and the error."""
    from datetime import date

    from mkdocs.exceptions import PluginError

    where.mkdir(parents=True, exist_ok=True)
    start, end = walkthrough_section(markdown)

    def run(m: re.Match) -> str:
        persona, block = m.group(2), m.group(3)
        before = {p for p in where.rglob("*") if p.is_file()}
        code, seconds, err = run_block(block, where)
        if code != 0 or "Traceback" in err:
            raise PluginError(f"docs/tutorials.md: the {persona} walk-through failed (exit {code}) in {where}:\n"
                              f"{err[-3000:]}")
        made = len({p for p in where.rglob("*") if p.is_file()} - before)
        return (f"{m.group(1)}\n\n*Run when this page was built ({date.today().isoformat()}): every command "
                f"exited 0, {seconds:.0f} s, {made} file{'' if made == 1 else 's'} written.*\n")

    return markdown[:start] + BLOCK.sub(run, markdown[start:end]) + markdown[end:]


def command_help() -> str:
    """Markdown: ``eoloc --help`` and every command's ``--help``, each in a text block."""
    import click

    from eoloc.cli.main import main

    width = {"terminal_width": 100, "max_content_width": 100}
    ctx = click.Context(main, info_name="eoloc", **width)
    out = ["## eoloc", "", "```text", main.get_help(ctx), "```", ""]
    for name in main.list_commands(ctx):
        cmd = main.get_command(ctx, name)
        sub = click.Context(cmd, info_name=name, parent=ctx, **width)
        out += [f"## eoloc {name}", "", "```text", cmd.get_help(sub), "```", ""]
    return "\n".join(out)


def readme() -> str:
    """The repository's README as the site's home page: its links into docs/ made relative to it,
    the files outside the site named as code."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    text = text.replace("](docs/", "](")
    return re.sub(r"\[([^]]+)\]\((?!https?:)([^)]+)\)", lambda m: m.group(0) if m.group(2).endswith(".md") and
                  "/" not in m.group(2) else f"`{m.group(2)}`", text)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri == "tutorials.md" and os.environ.get(WALK):
        markdown = run_walkthroughs(markdown, Path(os.environ[WALK]).resolve())
    if MARK in markdown:
        markdown = markdown.replace(MARK, command_help())
    if README in markdown:
        markdown = readme()
    return CITATION.sub(r"\\[\1\\]", markdown) if "```" not in markdown else _outside_code(markdown)


def _outside_code(markdown: str) -> str:
    """The citation marks escaped outside fenced code blocks only."""
    parts = re.split(r"(```.*?```)", markdown, flags=re.S)
    return "".join(p if p.startswith("```") else CITATION.sub(r"\\[\1\\]", p) for p in parts)


def on_page_content(html: str, page, config, files) -> str:
    """Headings that begin with a number ("## 2. What carries the design") get ids that begin with
    one, which are not CSS selectors: the theme's scroll spy stops on them. Such ids (and the links
    and table of contents that point to them) take an "h" in front."""

    def fix(items) -> None:
        for item in items:
            if item.id[:1].isdigit():
                item.id = "h" + item.id
            fix(item.children)

    fix(page.toc)
    html = re.sub(r'id="(\d)', r'id="h\1', html)
    return re.sub(r'href="#(\d)', r'href="#h\1', html)
