"""report.html: every metric with its bound and verdict, the plots, the diagram, the
scenario, and nothing loaded from outside the file."""

from __future__ import annotations

import base64
import json
from html.parser import HTMLParser
from pathlib import Path

import yaml

from nsdrake.reporting.metrics import Metric, describe, unit_words
from nsdrake.reporting.replay import DiagramPicture
from nsdrake.reporting.report import flatten, render_report


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
        assert unit == unit_words(m.unit)
        assert float(value) == float(f"{m.value:.6g}")
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
