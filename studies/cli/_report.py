"""``flexvib plot`` and ``flexvib report``: the figures of a result file, and a one-page report
(``report.md`` and ``report.html``) with the summary table and those figures beside it."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any, Mapping, Sequence

from .._kind import in_run_order, kind_of, summaries
from .._summary import markdown_table

REPORT_NAME = "report"


def write_figures(results: Mapping[str, Any], outdir: Path, extensions: Sequence[str] = ("png", "svg"),
                  *, dpi: int = 150) -> dict[str, list[Path]]:
    """Draw every figure of every study (its kind's ``figures``) into ``outdir`` as
    ``<study><suffix>.<extension>``; returns {study: [paths]}."""
    import matplotlib

    matplotlib.use("Agg")
    matplotlib.rcParams["svg.fonttype"] = "none"  # keep text as text: editable and searchable
    import matplotlib.pyplot as plt

    outdir.mkdir(parents=True, exist_ok=True)
    written: dict[str, list[Path]] = {}
    for name, result in results.items():
        for suffix, draw in kind_of(result).figures(result).items():
            figure = draw().figure
            for extension in extensions:
                target = outdir / f"{name}{suffix}.{extension}"
                figure.savefig(target, dpi=dpi)
                written.setdefault(name, []).append(target)
            plt.close(figure)
    return written


def _messages(results: Mapping[str, Any]) -> dict[str, str]:
    """Each single study's message (grid studies say theirs per point, in the table's status)."""
    return {name: str(result.message) for name, result in results.items()
            if not getattr(result, "is_grid", False) and result.message}


def markdown(results: Mapping[str, Any], figures: Mapping[str, list[Path]], *, title: str) -> str:
    """The report in Markdown: the summary table, each study's message and its figures (relative
    links)."""
    lines = [f"# {title}", "", markdown_table(summaries(results)), ""]
    messages = _messages(results)
    for name in results:
        lines += [f"## {name}", ""]
        if name in messages:
            lines += [messages[name], ""]
        lines += [f"![{name}: {path.stem}]({path.name})" for path in figures.get(name, [])] + [""]
    return "\n".join(lines)


def html_page(results: Mapping[str, Any], figures: Mapping[str, list[Path]], *, title: str) -> str:
    """The same report as one HTML page (no external assets but the PNG files beside it)."""
    from .._summary import COLUMNS, table_rows

    escape = html.escape
    head = "".join(f"<th>{escape(c)}</th>" for c in COLUMNS)
    body = "".join("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in row) + "</tr>"
                   for row in table_rows(summaries(results)))
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{escape(title)}</title>",
             "<style>body{font-family:sans-serif;max-width:60em;margin:auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}"
             "img{max-width:100%}</style></head><body>",
             f"<h1>{escape(title)}</h1><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"]
    messages = _messages(results)
    for name in results:
        parts.append(f"<h2>{escape(name)}</h2>")
        if name in messages:
            parts.append(f"<p>{escape(messages[name])}</p>")
        parts += [f"<img src='{escape(path.name)}' alt='{escape(name)}: {escape(path.stem)}'>"
                  for path in figures.get(name, [])]
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(results: Mapping[str, Any], outdir: str | Path, *, source: str | Path = "") -> list[Path]:
    """Write ``report.md``, ``report.html`` and the PNG figures into ``outdir``; returns the paths
    (the two reports first)."""
    outdir = Path(outdir)
    results = in_run_order(results)
    figures = write_figures(results, outdir, ("png",))
    title = f"flexvib report: {Path(source).name}" if source else "flexvib report"
    written = [outdir / f"{REPORT_NAME}.md", outdir / f"{REPORT_NAME}.html"]
    written[0].write_text(markdown(results, figures, title=title), encoding="utf-8")
    written[1].write_text(html_page(results, figures, title=title), encoding="utf-8")
    return written + [path for paths in figures.values() for path in paths]
