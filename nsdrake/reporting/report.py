"""report.html: one run on one page, opened from the file system with no network.

The page holds the scenario's parameters, every metric with its bound and
whether it passed, the plots (PNG, inlined as base64), the diagram's picture
(the SVG inlined, or the .dot source and how to render it), and relative links
to the replay and the run's other files. It loads nothing from anywhere: no
script, no font, no style sheet outside the file.
"""

from __future__ import annotations

import base64
import datetime
import html
from collections.abc import Iterable, Sequence
from pathlib import Path

from nsdrake.reporting.metrics import Metric
from nsdrake.reporting.replay import DiagramPicture

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 72em; padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; margin-top: 1.8em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.92em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.pass { color: #176b2c; font-weight: bold; }
.fail { color: #b0151b; font-weight: bold; }
.none { color: #888; }
.banner { display: inline-block; padding: 0.3em 0.8em; border-radius: 0.3em; font-weight: bold; }
.banner.pass { background: #dff3e4; }
.banner.fail { background: #fadcdc; }
.figure img { max-width: 100%; height: auto; }
.diagram { overflow-x: auto; border: 1px solid #eee; padding: 0.5em; }
.diagram svg { width: 2400px; max-width: none; height: auto; }
pre { background: #f7f7f7; padding: 0.6em; overflow-x: auto; font-size: 0.85em; }
.muted { color: #666; font-size: 0.9em; }
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def flatten(data, prefix: str = "") -> list[tuple[str, object]]:
    """Nested mappings as (dotted.name, value) rows; lists of numbers stay one value."""
    rows: list[tuple[str, object]] = []
    if isinstance(data, dict):
        for key, value in data.items():
            name = f"{prefix}.{key}" if prefix else str(key)
            if isinstance(value, dict) and value:
                rows.extend(flatten(value, name))
            else:
                rows.append((name, value))
    else:
        rows.append((prefix, data))
    return rows


def _format_value(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_format_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{}" if not value else ", ".join(f"{k}: {_format_value(v)}" for k, v in value.items())
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _metric_rows(metrics: Sequence[Metric]) -> str:
    rows = []
    for m in metrics:
        if m.passed is None:
            verdict = '<td class="none">no bound</td>'
        elif m.passed:
            verdict = '<td class="pass">&#10003; pass</td>'
        else:
            verdict = '<td class="fail">&#10007; FAIL</td>'
        rows.append(
            f'<tr data-metric="{_e(m.name)}"><td><code>{_e(m.name)}</code></td>'
            f'<td class="num">{_e(f"{m.value:.6g}")}</td><td>{_e(m.unit)}</td>'
            f"<td>{_e(m.bound) if m.bound else '&mdash;'}</td>{verdict}</tr>"
        )
    return "\n".join(rows)


def _inline_svg(svg_text: str) -> str:
    """The <svg> element of an SVG file, without its XML prologue and doctype."""
    start = svg_text.find("<svg")
    return svg_text[start:] if start >= 0 else ""


def _png_data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def render_report(
    *,
    title: str,
    description: str,
    parameters: dict,
    metrics: Sequence[Metric],
    plots: Iterable[Path],
    diagram: DiagramPicture | None,
    replay: str | None,
    files: Iterable[str],
    notes: Iterable[str] = (),
    failure: str | None = None,
) -> str:
    """The report page as a string; paths in ``replay`` and ``files`` are relative links.
    ``failure``: why the run stopped early (it is then marked failed)."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>{_e(title)}</h1>",
        f'<p class="muted">{_e(description)}</p>' if description else "",
        f"<p>{_banner(metrics, failure)}</p>",
    ]
    if replay:
        parts.append(
            f'<p>&#9654; <a id="replay-link" href="{_e(replay)}">Replay in 3D</a> '
            '<span class="muted">(Meshcat: the arm, the plate and the contact force; '
            "time slider under Open Controls &rarr; Animations)</span></p>"
        )
    parts += [f'<p class="muted">{_e(note)}</p>' for note in notes]
    parts += [
        '<h2 id="metrics">Metrics</h2>',
        "<table><thead><tr><th>metric</th><th>value</th><th>unit</th><th>bound</th>"
        "<th>result</th></tr></thead><tbody>",
        _metric_rows(metrics),
        "</tbody></table>",
    ]
    parts += _plot_section(plots) + _diagram_section(diagram) + _scenario_and_files(parameters, files)
    return "\n".join(p for p in parts if p)


def _banner(metrics: Sequence[Metric], failure: str | None) -> str:
    """The verdict at the top: the run failed, bounded metrics failed, or all pass."""
    bounded = [m for m in metrics if m.passed is not None]
    failed = [m for m in bounded if not m.passed]
    if failure:
        return (
            f'<span class="banner fail">run FAILED: {_e(failure)}; '
            "everything below is up to that moment</span>"
        )
    if failed:
        return (
            f'<span class="banner fail">{len(failed)} of {len(bounded)} bounded metrics FAIL: '
            f"{_e(', '.join(m.name for m in failed))}</span>"
        )
    return f'<span class="banner pass">all {len(bounded)} bounded metrics pass</span>'


def _plot_section(plots: Iterable[Path]) -> list[str]:
    """Each plot as an inlined PNG; nothing without plots."""
    plots = list(plots)
    if not plots:
        return []
    return ['<h2 id="plots">Plots</h2>'] + [
        f'<div class="figure"><img alt="{_e(Path(plot).name)}" src="{_png_data_uri(plot)}"></div>'
        for plot in plots
    ]


def _diagram_section(diagram: DiagramPicture | None) -> list[str]:
    """The diagram's SVG inlined, or, without Graphviz, the note and the .dot source."""
    parts = ['<h2 id="diagram">Diagram</h2>']
    if diagram is not None and diagram.svg is not None:
        parts.append(
            '<p class="muted">Every system of the Drake diagram, named after its role, and the signals '
            "between them, from the plant's outputs (left) to its inputs (right); scroll, or open "
            f'<a href="{_e(diagram.svg.name)}">{_e(diagram.svg.name)}</a> '
            f'(source: <a href="{_e(diagram.dot.name)}">{_e(diagram.dot.name)}</a>).</p>'
        )
        parts.append(f'<div class="diagram">{_inline_svg(diagram.svg.read_text(encoding="utf-8"))}</div>')
    elif diagram is not None:
        parts.append(f"<p>{_e(diagram.note)}</p>")
        parts.append(
            f"<details><summary>{_e(diagram.dot.name)}</summary><pre>"
            f"{_e(diagram.dot.read_text(encoding='utf-8'))}</pre></details>"
        )
    return parts


def _scenario_and_files(parameters: dict, files: Iterable[str]) -> list[str]:
    """The scenario's parameters as a table, the links to the run's files, the footer."""
    generated = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    return [
        '<h2 id="scenario">Scenario</h2>',
        "<table><thead><tr><th>parameter</th><th>value</th></tr></thead><tbody>",
        "\n".join(
            f"<tr><td><code>{_e(name)}</code></td><td>{_e(_format_value(value))}</td></tr>"
            for name, value in flatten(parameters)
        ),
        "</tbody></table>",
        '<h2 id="files">Files</h2><ul>',
        "\n".join(f'<li><a href="{_e(name)}">{_e(name)}</a></li>' for name in files),
        "</ul>",
        f'<p class="muted">Written by nsdrake on {_e(generated)}.</p>',
        "</body></html>",
    ]


def write_report(out: Path, **kwargs) -> Path:
    """Writes ``out/report.html`` (see :func:`render_report` for the arguments);
    ``files`` defaults to every file in ``out`` at the time of writing."""
    out = Path(out)
    path = out / "report.html"
    if "files" not in kwargs:
        kwargs["files"] = sorted(
            p.name for p in out.iterdir() if p.is_file() and p.name != "report.html" and p.name[0] != "."
        )
    path.write_text(render_report(**kwargs), encoding="utf-8")
    return path
