"""MkDocs hooks of eoloc's documentation site: the command-line reference written from the
commands' own ``--help`` (click, in this process: what a user sees, never a copy that drifts), and
the papers' citation marks ([S13], [Z15], [Q], [P]) kept as text rather than read as links."""

from __future__ import annotations

import re

MARK = "<!-- eoloc commands -->"
README = "<!-- eoloc readme -->"
CITATION = re.compile(r"(?<![\\\w])\[([A-Z][A-Za-z0-9]{0,4})\](?![(\[:])")


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
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    text = text.replace("](docs/", "](")
    return re.sub(r"\[([^]]+)\]\((?!https?:)([^)]+)\)", lambda m: m.group(0) if m.group(2).endswith(".md") and
                  "/" not in m.group(2) else f"`{m.group(2)}`", text)


def on_page_markdown(markdown: str, page, config, files) -> str:
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
