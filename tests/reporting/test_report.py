"""report.html: every metric with its bound and verdict, the plots, the diagram, the
scenario, and nothing loaded from outside the file."""

from __future__ import annotations

import base64
import json
from html.parser import HTMLParser
from pathlib import Path

import pytest
import yaml

from nsdrake.reporting.metrics import Metric, describe, unit_words
from nsdrake.reporting.replay import DiagramPicture
from nsdrake.reporting.report import flatten, render_report

PREFIX = {"": 1.0, "m": 1e-3, "µ": 1e-6, "n": 1e-9, "p": 1e-12}


class _Page(HTMLParser):
    """The parts of a page the tests look at: links and sources, metric rows, tags."""

    def __init__(self, text: str):
        super().__init__()
        self.references: list[tuple[str, str, str]] = []  # (tag, attribute, value)
        self.rows: dict[str, list[str]] = {}
        self.tags: list[str] = []
        self._row: str | None = None
        self._cell: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        a = dict(attrs)
        for name in ("href", "xlink:href", "src", "srcset", "action", "data", "poster"):
            if name in a:
                self.references.append((tag, name, a[name]))
        if tag == "tr" and "data-metric" in a:
            self._row = a["data-metric"]
            self.rows[self._row] = []
        if tag == "td" and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self.rows[self._row].append("".join(self._cell).strip())
            self._cell = None
        if tag == "tr":
            self._row = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _read(out: Path) -> tuple[str, _Page]:
    text = (out / "report.html").read_text(encoding="utf-8")
    return text, _Page(text)


def test_report_lists_every_metric_with_its_bound_and_verdict(short_run):
    out, result = short_run
    _, page = _read(out)
    written = json.loads((out / "metrics.json").read_text())["metrics"]
    assert set(page.rows) == set(written) == {m.name for m in result.metrics}
    for m in result.metrics:
        what, value, unit, bound, verdict = page.rows[m.name]
        assert what.startswith(describe(m.name)) and what.endswith(m.name)  # words first, the key after
        # the value in engineering units: the number times its unit's prefix is the metric
        # to the 4 significant digits shown
        prefix = unit[: len(unit) - len(unit_words(m.unit))] if unit != unit_words(m.unit) else ""
        assert unit_words(prefix + m.unit) == unit, (m.name, unit)
        assert float(value) * PREFIX[prefix] == pytest.approx(m.value, rel=5e-4, abs=1e-300), (m.name, value)
        assert bound == (m.bound or "—")
        assert verdict == {None: "no bound", True: "✓ pass", False: "✗ FAIL"}[m.passed]


def test_report_needs_nothing_outside_its_folder(short_run):
    out, _ = short_run
    text, page = _read(out)
    assert page.references, "the page links the replay and the run's files"
    for tag, attribute, value in page.references:
        if value.startswith("data:"):
            continue
        if value.startswith("#"):  # a section of the page itself
            assert f'id="{value[1:]}"' in text, value
            continue
        assert "://" not in value and not value.startswith(("/", "//")), (tag, attribute, value)
        assert (out / value).is_file(), value  # every relative link resolves
    assert "<link" not in text and "@import" not in text and "url(" not in text.replace("xlink", "")
    assert "<script" not in text


def test_report_inlines_the_plots_and_the_diagram_and_links_the_replay(short_run):
    out, _ = short_run
    text, page = _read(out)
    images = [v for tag, a, v in page.references if tag == "img"]
    # fig3's checks are [fig3, priority]: its two plots, in that order, inlined byte for byte.
    assert len(images) == 2 and all(i.startswith("data:image/png;base64,") for i in images)
    for image, name in zip(images, ("fig3.png", "priority.png"), strict=True):
        assert base64.b64decode(image.split(",", 1)[1]) == (out / name).read_bytes()
    if (out / "diagram.svg").exists():
        assert "svg" in page.tags and "name=impedance_controller" in text
    else:
        assert "diagram.dot" in text and "dot -Tsvg" in text
    assert ("a", "href", "replay.html") in page.references


def test_report_shows_every_scenario_parameter(short_run):
    out, _ = short_run
    text, _ = _read(out)
    parameters = yaml.safe_load((out / "scenario.yaml").read_text())
    rows = flatten(parameters)
    assert len(rows) > 30
    for name, _value in rows:
        assert f"<code>{name}</code>" in text, name
    assert "<code>impedance.K_p_tangent</code></td><td>400" in text


def test_a_failed_metric_is_marked_and_counted(tmp_path):
    dot = tmp_path / "diagram.dot"
    dot.write_text("digraph { a -> b }")
    metrics = [
        Metric("force_error_rms", 0.5, "N", "<= 0.2 N", False),
        Metric("tangential_position_error_rms", 1e-4, "m", "<= 0.001 m", True),
        Metric("first_contact_time", 1.27, "s", "", None),
    ]
    text = render_report(
        title="t",
        description="",
        parameters={"a": {"b": 1.0}},
        metrics=metrics,
        plots=[],
        diagram=DiagramPicture(dot, None, "Graphviz's dot was not found: wrote diagram.dot only"),
        replay=None,
        files=["diagram.dot"],
    )
    page = _Page(text)
    assert "1 of 2 bounded metrics FAIL: force_error_rms" in text
    assert page.rows["force_error_rms"][-1] == "✗ FAIL"
    assert page.rows["tangential_position_error_rms"][-1] == "✓ pass"
    assert page.rows["first_contact_time"][-1] == "no bound"
    assert "replay" not in text.lower()  # no replay, no dangling link
    assert "a -&gt; b" in text  # the .dot source, escaped, when there is no SVG


def test_every_metric_is_described_in_words(short_run):
    """Every metric fig3's report shows has a plain description, and so has every metric
    name metrics.py can make (its Metric(...) calls, f-string names filled with examples).
    Catches a metric added with only its internal name (``window_rows``,
    ``mode2_p_tau_change_min``) for the reader."""
    import re

    from nsdrake.reporting import metrics as metrics_module

    _, result = short_run
    assert [m.name for m in result.metrics if not describe(m.name)] == []
    source = Path(metrics_module.__file__).read_text()
    names = re.findall(r'Metric\(\s*(f?"[^"]+")', source)
    assert len(names) > 25
    examples = {
        "{m}": "2",
        "{column}": "p_tau",
        "{D_MIN_AFTER:g}": "1",
        "{name}": "post",
        "{kind}": "q",
        "{i + 1}": "3",
    }
    filled = []
    for literal in names:
        name = literal.lstrip("f").strip('"')
        for field, example in examples.items():
            name = name.replace(field, example)
        filled.append(name)
    assert [n for n in filled if not describe(n) or "{" in n] == []
    assert "the joint-torque criterion" in describe("mode2_p_tau_change_min")
    assert "obstacle 'post'" in describe("d_post_min")


def test_the_title_says_what_the_run_did(short_run):
    """The title names the modes the run visited and no other (fig3's description promises
    obstacle avoidance; a run that stays in mode 2 must not), and when contact began."""
    from nsdrake.experiment.traces import Traces
    from nsdrake.reporting.report import MODE_WORDS

    out, _ = short_run
    text, _ = _read(out)
    title = text.split("<h1>", 1)[1].split("</h1>", 1)[0]
    visited = {int(m) for m in Traces.read_csv(out / "traces.csv")["mode"]}
    for mode, words in MODE_WORDS.items():
        assert (f"{words} (" in title or f"{words} throughout" in title) == (mode in visited), (mode, title)
    assert "contact from t = " in title and title.startswith("fig3, 2 s")


def test_the_scenario_table_shows_what_the_scenario_sets_first(short_run):
    """The parameters fig3 changes from the defaults (K_n 100, its start pose) come first,
    the defaults (the realism ladder, the driver) folded away in a details element; every
    parameter is still on the page once."""
    out, _ = short_run
    text, _ = _read(out)
    scenario = text.split('<h2 id="scenario">', 1)[1].split('<h2 id="files">', 1)[0]
    shown, folded = scenario.split("<details>", 1)
    assert "<code>null_space.K_n</code></td><td>100" in shown
    assert "<code>arm.initial_positions.joint1</code>" in shown
    assert "<code>realism.belt.enabled</code>" in folded and "<code>realism.belt.enabled</code>" not in shown
    assert "<code>impedance.K_p_tangent</code>" in folded  # 400, fig3's value, is the default
    parameters = yaml.safe_load((out / "scenario.yaml").read_text())
    for name, _ in flatten(parameters):
        assert scenario.count(f"<code>{name}</code>") == 1, name


def test_the_modes_are_explained_and_linked(short_run):
    """The report explains Fig. 1's tree with the run's thresholds, and every mode it shows
    (a mode metric, a plot with the mode) links that section."""
    out, result = short_run
    text, page = _read(out)
    assert '<h2 id="modes">' in text and "d_lim = 0.03 m" in text and "w_lim = 0.005 m²" in text
    for m in result.metrics:
        if m.name.startswith("mode"):
            row = text.split(f'data-metric="{m.name}"', 1)[1].split("</tr>", 1)[0]
            assert 'href="#modes"' in row, m.name
    captions = text.split("<figcaption>")[1:]
    assert len(captions) == 2 and all('href="#modes"' in c for c in captions)


def _visible(text: str) -> str:
    """The page without its inlined pictures (base64 PNGs, an SVG) and its style sheet
    (colours such as #dff3e4): what a reader reads."""
    import re

    text = re.sub(r'src="data:[^"]*"', 'src=""', text)
    return re.sub(r"<svg.*?</svg>|<style>.*?</style>", "", text, flags=re.S)


def test_no_value_in_e_notation_and_no_machine_path(short_run):
    """Every figure on fig3's page (metrics, bounds, loops, the controller box, the
    scenario's parameters) is in engineering units, never e-notation (62.91 µm, not
    6.29073e-05 m); the scenario is named by its file's name and neither the scenario's
    folder nor the run's absolute path appears. Catches a value printed with :g (the old
    :.6g), a parameter like the rate limit's 1e9, or the subtitle's scenario.source."""
    import re

    from nsdrake.experiment.scenario import load_scenario

    out, _ = short_run
    text = _visible((out / "report.html").read_text(encoding="utf-8"))
    assert re.findall(r"\d(?:\.\d+)?[eE][+-]?\d", text) == []
    source = Path(load_scenario("fig3").source)
    assert "(fig3.yaml, folder" in text
    assert str(source.parent) not in text and str(out.resolve()) not in text
    # a parameter at the ends of the range (the family's 1e9 N m/s "no rate limit", a 1e-5 step)
    text = render_report(
        title="t",
        description="",
        parameters={"torque_rate": 1e9, "step": 1e-5},
        metrics=[Metric("tangential_position_error_rms", 6.29073e-05, "m", "<= 1 mm", True)],
        plots=[],
        diagram=None,
        replay=None,
        files=[],
    )
    assert re.findall(r"\d(?:\.\d+)?[eE][+-]?\d", _visible(text)) == []
    assert "1 × 10⁹" in text and "1 × 10⁻⁵" in text and ">62.91</td><td>µm<" in text


def test_the_report_opens_with_the_controller_and_its_loops(short_run):
    """Before the metrics: the controller box (period, the task's gains per axis, K_f,
    f_d, the law, its projector, K_n) and the loops, whose figures are checked against
    closed forms: along the plate ẍ = −400 x − 40 ẋ, ζ = 40/(2√400) = 1, slowest pole
    20 rad/s, the Jury margin 2/(K_v T) = 25; fig3's null space, the velocity loop
    ėⁿ = −K_n eⁿ: pole K_n = 100 rad/s, margin 2/(K_n T) = 10 without delay and, with one
    period of delay (z² − z + g K_n T = 0), 1/(K_n T) = 5. Catches the box or the loops
    missing or after the metrics, the two margins swapped, or a loop read off the wrong
    gains."""
    out, _ = short_run
    text, page = _read(out)
    assert text.index('id="controller"') < text.index('id="loops"') < text.index('id="metrics"')
    box = text.split('id="controller"', 1)[1].split("</table>", 1)[0]
    for shown in (
        "control period T</th><td>2 ms",
        "task axis x (along the plate)</th><td>K_p 400 1/s², K_v 40 1/s",
        "task axis y (normal to the plate)</th><td>K_p 100 1/s², K_v 200 1/s",
        "force gain K_f</th><td>1 m/(s² N)",
        "desired force f_d</th><td>10 N",
        "null-space velocity gain K_n</th><td>100 1/s",
        "null-space projector</th><td>I − J̄ J with the dynamically consistent J̄",
    ):
        assert shown in box, shown
    loops = {}
    for row in text.split('<tr data-loop="')[1:]:
        name, rest = row.split("</tr>", 1)[0].split('"', 1)
        loops[name] = [c.split("</td>")[0] for c in rest.split('<td class="num">')[1:]]

    def figures(name):
        zeta, pole, margin, delayed = loops[name]
        return zeta, float(pole.removesuffix(" rad/s")), float(margin[2:]), float(delayed[2:])

    zeta, pole, margin, delayed = figures("task, along the plate")
    assert (zeta, pole) == ("1", 20.0) and margin == pytest.approx(25.0, rel=1e-3) and 1.0 < delayed < margin
    zeta, pole, margin, delayed = figures("null space: the velocity loop ėⁿ = −K_n eⁿ")
    assert (zeta, pole) == ("n/a (first order)", 100.0)
    assert margin == pytest.approx(10.0, rel=1e-3) and delayed == pytest.approx(5.0, rel=1e-3)


def test_a_metric_the_law_does_not_have_reads_na_not_fail(short_run):
    """fig3's traces measured as the run of a posture-PD law (dynamically consistent torque
    PD): it has no q̇_dⁿ and no eⁿ, so null_space_error_rms and null_space_command_rms are
    n/a, ungraded (the report's result column reads n/a, the banner does not count them),
    where the paper's law with the same, non-finite, eⁿ is graded FAIL. Catches a report
    that grades a figure the law lacks (the nan compared with its bound: FAIL)."""
    import dataclasses
    import math

    from nsdrake.experiment.diagram import build_diagram
    from nsdrake.experiment.scenario import load_scenario
    from nsdrake.experiment.traces import Traces
    from nsdrake.reporting.run_folder import compute_metrics

    out, _ = short_run
    traces = Traces.read_csv(out / "traces.csv")
    columns = {name: traces[name] for name in traces.names}
    for name in columns:
        if name.startswith(("en", "qns")) and name[-1].isdigit():
            columns[name] = columns[name] * math.nan  # what a posture law logs: no eⁿ
    traces = Traces(columns)
    scenario = load_scenario("fig3", duration=2.0)
    station = build_diagram(scenario).station
    pd = dataclasses.replace(
        scenario, null_space=dataclasses.replace(scenario.null_space, law="dynamically_consistent_torque_pd")
    )
    for law_scenario, graded in ((pd, False), (scenario, True)):
        metrics = compute_metrics(law_scenario, station, traces, None)
        error = next(m for m in metrics if m.name == "null_space_error_rms")
        assert (error.passed is not None) == graded, law_scenario.null_space.law
        text = render_report(
            title="t",
            description="",
            parameters={},
            metrics=metrics,
            plots=[],
            diagram=None,
            replay=None,
            files=[],
        )
        verdict = _Page(text).rows["null_space_error_rms"][-1]
        assert verdict == ("✗ FAIL" if graded else "n/a"), verdict
        banner = text.split('class="banner', 1)[1].split("</span>", 1)[0]
        assert ("null_space_error_rms" in banner) == graded, banner
