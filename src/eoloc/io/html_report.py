"""One self-contained HTML page from blocks (headings, text, tables, pictures, preformatted text):
the pictures inline as PNG data URIs, the style in the page, no script and nothing fetched, so the
report opens offline, mails as one file and prints as it shows."""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field
from pathlib import Path

_STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:2em auto;max-width:1150px;
color:#1d1d1f;line-height:1.45;padding:0 1em}
h1{font-size:1.7em;margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:1.8em}
h3{margin-top:1.3em}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right;vertical-align:top}
th{background:#f3f3f5}td.l,th.l{text-align:left}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.9em;color:#555}
pre{background:#f7f7f9;border:1px solid #e3e3e8;padding:.7em;overflow-x:auto;font-size:.85em}
.note{color:#8a5a00}.key{display:flex;gap:1.5em;flex-wrap:wrap}
.key div{background:#f3f6fb;border:1px solid #d5dff0;border-radius:6px;padding:.5em 1em}
.key b{display:block;font-size:1.35em}
@media print{figure{break-inside:avoid}}
"""


@dataclass
class Page:
    """Blocks of a report, in order. Every text is escaped when the page is rendered."""

    title: str
    blocks: list[str] = field(default_factory=list)
    figures: int = 0

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def text(self, text: str, cls: str = "") -> None:
        attr = f' class="{cls}"' if cls else ""
        self.blocks.append(f"<p{attr}>{html.escape(text)}</p>")

    def items(self, texts: list[str], cls: str = "") -> None:
        if texts:
            attr = f' class="{cls}"' if cls else ""
            self.blocks.append(f"<ul{attr}>" + "".join(f"<li>{html.escape(t)}</li>" for t in texts) + "</ul>")

    def key_figures(self, pairs: list[tuple[str, str]]) -> None:
        self.blocks.append('<div class="key">' + "".join(
            f"<div>{html.escape(k)}<b>{html.escape(v)}</b></div>" for k, v in pairs) + "</div>")

    def table(self, header: list[str], rows: list[list], caption: str = "", align: str = "l") -> None:
        """A table; ``align``: per column "l" (labels) or "r" (numbers), the missing ones "r"."""
        align = align.ljust(len(header), "r")

        def cell(tag: str, i: int, v) -> str:
            cls = ' class="l"' if align[i] == "l" else ""
            return f"<{tag}{cls}>{html.escape(_text(v))}</{tag}>"

        head = "<tr>" + "".join(cell("th", i, h) for i, h in enumerate(header)) + "</tr>"
        body = "".join("<tr>" + "".join(cell("td", i, v) for i, v in enumerate(r)) + "</tr>" for r in rows)
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self.blocks.append(f"<table>{cap}<thead>{head}</thead><tbody>{body}</tbody></table>")

    def table_data(self, t) -> None:
        """A table given as data (eoloc.jobs.evaluate.TableData), its title as a heading."""
        self.heading(t.title, 3)
        self.table(t.header, t.rows, t.caption, t.alignment())

    def figure(self, png: bytes, caption: str, name: str) -> None:
        data = base64.b64encode(png).decode("ascii")
        self.figures += 1
        self.blocks.append(f'<figure data-figure="{html.escape(name)}"><img alt="{html.escape(caption)}" '
                           f'src="data:image/png;base64,{data}"><figcaption>{html.escape(caption)}</figcaption>'
                           "</figure>")

    def pre(self, text: str) -> None:
        self.blocks.append(f"<pre>{html.escape(text)}</pre>")

    def render(self) -> str:
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
                f"<title>{html.escape(self.title)}</title><style>{_STYLE}</style></head>\n"
                f"<body data-figures=\"{self.figures}\"><h1>{html.escape(self.title)}</h1>\n"
                + "\n".join(self.blocks) + "\n</body></html>\n")

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.render(), encoding="utf-8")
        return path


def _text(v) -> str:
    if v is None:
        return "—"
    if isinstance(v, float):
        return "—" if v != v else f"{v:.2f}"
    return str(v)
