"""report.html: one run on one page, opened from the file system with no network.

The page opens with the controller as the run set it up (period, the task's gains per
axis, the force loop, the null-space law, its projector and gains) and its loops' figures
(damping ratio, slowest pole, gain margin without and with a period's delay:
:mod:`nsdrake.reporting.loops`), then holds every metric with its bound and whether it
passed (n/a, ungraded, where the run's law has no such figure), every value in
engineering units (:mod:`nsdrake.reporting.units`: 62.91 µm, never e-notation), the
scenario's parameters, the plots (PNG, inlined as base64), the diagram's picture
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

from nsdrake.reporting.metrics import NO_LAW_FIGURE, Metric, describe, unit_words
from nsdrake.reporting.replay import DiagramPicture
from nsdrake.reporting.units import number, split_quantity

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 72em; padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; margin-top: 1.8em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.92em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; }
table.box th { text-align: left; font-weight: normal; white-space: nowrap; }
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
.name { color: #777; font-size: 0.8em; }
figcaption { color: #444; font-size: 0.9em; margin: 0.2em 0 1.2em; }
details > summary { cursor: pointer; margin: 0.6em 0; }
"""

# What each plot shows, under it; a plot with the mode links the modes' section.
PLOT_CAPTIONS = {
    "fig3.png": "Fig. 3's panels: the contact force against its setpoint, the tool's position along the "
    'plate, the null-space velocity error and, at the bottom, the <a href="#modes">mode</a> (which '
    "criterion is on level 2) with the closest link–obstacle distance d_min and the manipulability w.",
    "priority.png": 'Fig. 1\'s switching: the <a href="#modes">mode</a> over time, and each criterion '
    "while its mode has it on level 2 (it should improve there), with the torque steps at switches.",
    "pose.png": "The pose task: force, the tool's path on the surface, position and orientation errors, "
    'obstacle distances, joint-limit margins, and the elbow\'s swivel with the <a href="#modes">mode</a>.',
}

# Fig. 1's modes: which criterion the null space serves first (level 2).
MODE_WORDS = {
    0: "no criterion configured",
    1: "obstacle avoidance",
    2: "joint-torque minimisation",
    3: "manipulability maximisation",
    4: "joint-limit avoidance",
}


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
        return number(value, 6)
    return str(value)


def _metric_rows(metrics: Sequence[Metric]) -> str:
    rows = []
    for m in metrics:
        value, unit = split_quantity(m.value, m.unit)
        if m.passed is None and m.bound.startswith(NO_LAW_FIGURE):
            verdict = '<td class="none">n/a</td>'
        elif m.passed is None:
            verdict = '<td class="none">no bound</td>'
        elif m.passed:
            verdict = '<td class="pass">&#10003; pass</td>'
        else:
            verdict = '<td class="fail">&#10007; FAIL</td>'
        words = describe(m.name) or m.name
        link = ' (<a href="#modes">modes</a>)' if m.name.startswith("mode") else ""
        rows.append(
            f'<tr data-metric="{_e(m.name)}"><td>{_e(words)}{link}<br>'
            f'<code class="name">{_e(m.name)}</code></td>'
            f'<td class="num">{_e(value)}</td><td>{_e(unit_words(unit))}</td>'
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
    defaults: dict | None = None,
    modes: Sequence[int] = (),
    controller: Sequence[tuple[str, str]] = (),
    loops: Sequence = (),
    delay_periods: int = 0,
) -> str:
    """The report page as a string; paths in ``replay`` and ``files`` are relative links.
    ``failure``: why the run stopped early (it is then marked failed). ``defaults``: the
    parameters of a scenario that sets nothing (the scenario table shows first what
    ``parameters`` changes from them, the rest folded away). ``modes``: the modes of Fig. 1
    the run visited, in order (the modes' section explains them). ``controller``: the
    controller as set up, (what, value) rows (:func:`nsdrake.reporting.loops.controller_box`),
    shown first; ``loops``: its loops' figures (:class:`nsdrake.reporting.loops.Loop`), and
    ``delay_periods`` the run's computation delay (which margin column applies)."""
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
            '<span class="muted">(Meshcat: the arm, the plate and the contact force; it opens at '
            "t = 0 with its play button and time slider at the top)</span></p>"
        )
    parts += [f'<p class="muted">{_e(note)}</p>' for note in notes]
    parts += _controller_section(controller) + _loops_section(loops, delay_periods)
    parts += [
        '<h2 id="metrics">Metrics</h2>',
        '<p class="muted">Each figure is computed from traces.csv (metrics.json holds the same); the '
        "grey name is its key in metrics.json.</p>",
        "<table><thead><tr><th>what it measures</th><th>value</th><th>unit</th><th>bound</th>"
        "<th>result</th></tr></thead><tbody>",
        _metric_rows(metrics),
        "</tbody></table>",
    ]
    parts += _plot_section(plots) + _modes_section(modes, parameters)
    parts += _diagram_section(diagram) + _scenario_and_files(parameters, files, defaults)
    return "\n".join(p for p in parts if p)


def _controller_section(rows: Sequence[tuple[str, str]]) -> list[str]:
    """The controller as the run set it up, one row per setting; nothing without rows."""
    if not rows:
        return []
    return [
        '<h2 id="controller">The controller</h2>',
        '<table class="box"><tbody>',
        "\n".join(f"<tr><th>{_e(what)}</th><td>{_e(value)}</td></tr>" for what, value in rows),
        "</tbody></table>",
    ]


def _margin(value: float) -> str:
    from nsdrake.reporting.sampled_loops import GAIN_MARGIN_MAX

    return f"> {number(GAIN_MARGIN_MAX)}" if value >= GAIN_MARGIN_MAX else f"× {number(value)}"


def _loops_section(loops: Sequence, delay_periods: int) -> list[str]:
    """The loops' figures: ζ, the slowest pole and the gain margin without and with one
    period of computation delay; nothing without loops."""
    if not loops:
        return []
    applies = "without delay" if delay_periods == 0 else "with a period's delay"
    rows = "\n".join(
        f'<tr data-loop="{_e(lp.name)}"><td>{_e(lp.name)}<br><span class="name">{_e(lp.gains)}</span></td>'
        f'<td class="num">{_e(lp.zeta) if lp.zeta else "n/a (first order)"}</td>'
        f'<td class="num">{_e(number(lp.slowest_pole))} rad/s</td>'
        f'<td class="num">{_e(_margin(lp.margin))}</td>'
        f'<td class="num">{_e(_margin(lp.margin_delay))}</td></tr>'
        for lp in loops
    )
    return [
        '<h2 id="loops">The loops</h2>',
        '<p class="muted">Each loop sampled at the control period with the torque held over it, with '
        "an exact model (each task direction a unit mass; the null space along each of its directions, "
        "at the start posture): the damping ratio ζ (a range over the null-space directions), the slowest "
        "pole, and the gain margin: the factor by which the acceleration the loop's torque produces may "
        "grow before the loop turns unstable, without delay and with one period of computation delay "
        "(the torque computed from the sample at t<sub>k</sub> applied from t<sub>k+1</sub>, as a real drive "
        "runs it). The force loop in contact sees the plate only through the sampled force term, "
        "not the plate's own push on the tool: its margins are the model's, a floor on "
        "fig3 (a run with a period's delay settles at twice its delayed margin; docs/laws.md). "
        f"This run: {applies}.</p>",
        "<table><thead><tr><th>loop</th><th>ζ</th><th>slowest pole</th><th>gain margin</th>"
        "<th>gain margin, a period's delay</th></tr></thead><tbody>",
        rows,
        "</tbody></table>",
    ]


def _modes_section(modes: Sequence[int], parameters: dict) -> list[str]:
    """Fig. 1's decision tree in words, with this scenario's thresholds, and the modes the
    run visited; nothing for a run without a mode column."""
    if not modes:
        return []
    selector = parameters.get("desired_null_space", {}).get("selector", {})
    value = lambda key: _e(_format_value(selector.get(key, "?")))  # noqa: E731
    visited = " &rarr; ".join(f"{m} ({_e(MODE_WORDS.get(m, '?'))})" for m in modes)
    return [
        '<h2 id="modes">Modes: Fig. 1\'s decision tree</h2>',
        "<p>Every control period the controller picks which secondary criterion the null space "
        "serves first (level 2; level 1 is always the position and force task). The first test "
        "that holds sets the mode, the <code>mode</code> column of traces.csv:</p><ol>",
        f"<li>a link closer to an obstacle than d_lim = {value('d_lim')} m &rarr; <b>1</b>, obstacle "
        "avoidance;</li>",
        f"<li>else a joint closer to a limit than q_lim = {value('q_lim')} rad (0: never) &rarr; "
        "<b>4</b>, joint-limit avoidance;</li>",
        f"<li>else the manipulability below w_lim = {value('w_lim')} m² &rarr; <b>3</b>, "
        "manipulability maximisation;</li>",
        "<li>else &rarr; <b>2</b>, joint-torque minimisation.</li></ol>",
        f"<p>Hysteresis: mode 1 is left only beyond d_lim + {value('d_band')} m, mode 4 beyond "
        f"q_lim + {value('q_band')} rad, mode 3 above w_lim + {value('w_band')} m²; after a switch "
        f"the null-space command blends to the new order over {value('blend_time')} s. Mode 0: no "
        "criterion configured. The other criteria take the lower levels (the documentation's page "
        "docs/decision_tree.md has the order of each mode).</p>",
        f"<p>This run: {visited}.</p>",
    ]


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
        f'<figure class="figure"><img alt="{_e(Path(plot).name)}" src="{_png_data_uri(plot)}">'
        f"<figcaption>{PLOT_CAPTIONS.get(Path(plot).name, _e(Path(plot).name))}</figcaption></figure>"
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


def _parameter_rows(rows: list[tuple[str, object]]) -> str:
    return "\n".join(
        f"<tr><td><code>{_e(name)}</code></td><td>{_e(_format_value(value))}</td></tr>"
        for name, value in rows
    )


def _scenario_and_files(parameters: dict, files: Iterable[str], defaults: dict | None = None) -> list[str]:
    """The scenario's parameters (what it changes from the defaults first, the rest folded
    away), the links to the run's files, the footer."""
    generated = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    rows = flatten(parameters)
    default = dict(flatten(defaults)) if defaults is not None else {}
    changed = [(n, v) for n, v in rows if defaults is None or n not in default or default[n] != v]
    unchanged = [(n, v) for n, v in rows if defaults is not None and n in default and default[n] == v]
    head = "<table><thead><tr><th>parameter</th><th>value</th></tr></thead><tbody>"
    parts = ['<h2 id="scenario">Scenario</h2>']
    if defaults is not None:
        parts.append(
            f'<p class="muted">What this scenario sets: the {len(changed)} parameters that differ from '
            "nsdrake's defaults (scenario.yaml holds every one; docs/scenario_fields.md explains each).</p>"
        )
    parts += [head, _parameter_rows(changed), "</tbody></table>"]
    if unchanged:
        parts += [
            f"<details><summary>The other {len(unchanged)} parameters, at their defaults</summary>",
            head,
            _parameter_rows(unchanged),
            "</tbody></table></details>",
        ]
    return parts + [
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
