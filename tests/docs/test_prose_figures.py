"""The docs' prose against the files behind it (issue 38), reading files only (no build, no
simulation):

- a figure written ``{nsdrake-figure}`162 µs <drive | loop alone | CPU p99.9>``` is
  the cell of docs/results/drive/table.md it names (docs/_ext/nsdrake_docs.py's
  ``figure_problem``, which the site's build runs too: a figure that differs is an error
  under ``sphinx-build -W``);
- every repository path a page names (README.md, docs/**/*.md, the tutorials' markdown
  cells, and the docstrings of nsdrake/, which the API page renders) exists;
- no page (those, and the result tables' prose) writes a measured-looking figure bare
  (issue 47): what stays bare is a set-up figure listed for its page with its reason, or in
  a section that is a dated log of timings by hand.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
nsdrake_docs = pytest.importorskip("nsdrake_docs", reason="the docs extra (sphinx) is not installed")


def pages() -> dict[str, str]:
    """Page path → its text: README.md, docs/**/*.md, the notebooks' markdown cells."""
    out = {"README.md": (ROOT / "README.md").read_text()}
    for page in sorted((ROOT / "docs").glob("**/*.md")):
        if "_build" not in page.parts and "results" not in page.parts:
            out[page.relative_to(ROOT).as_posix()] = page.read_text()
    for notebook in sorted((ROOT / "docs").glob("**/*.ipynb")):
        if "_build" in notebook.parts:
            continue
        cells = json.loads(notebook.read_text())["cells"]
        text = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
        out[notebook.relative_to(ROOT).as_posix()] = text
    return out


def figures(text: str) -> list[tuple[str, str]]:
    """(written figure, target) of each ``{nsdrake-figure}`` role in a page."""
    out = []
    for role in nsdrake_docs.FIGURE_ROLE.findall(text):
        match = nsdrake_docs.FIGURE.match(" ".join(role.split()))
        assert match, f"not 'FIGURE <RESULTS | ROW | COLUMN>': {role}"
        out.append((match.group("written"), match.group("target")))
    return out


def figure_problems(texts: dict[str, str]) -> list[str]:
    return [
        f"{page}: {problem}"
        for page, text in texts.items()
        for written, target in figures(text)
        if (problem := nsdrake_docs.figure_problem(ROOT, written, target))
    ]


def test_every_prose_figure_is_its_file():
    """Each figure the prose marks is the table cell it names, to the digits written.
    Catches a table regenerated without its prose (docs/real_arm.md said p99.9 0.4–0.5 ms
    against the table's 375/500 µs)."""
    texts = pages()
    assert sum(len(figures(t)) for t in texts.values()) >= 10  # the marked figures are found
    assert figure_problems(texts) == []


def test_a_figure_that_differs_is_caught():
    """The check fails on a changed digit, a dropped decimal that rounds wrong, a wrong
    unit prefix (µs for ms), a figure not in a prose cell, a row named twice: not a test
    that cannot fail."""
    texts = pages()
    # a whole-µs figure the pages mark (whichever the tables hold today: the pages follow them)
    page, text, number = next(
        (p, t, int(m.group(1)))
        for p, t in texts.items()
        for m in re.finditer(r"\{nsdrake-figure\}`(\d{3}) µs <", t)
    )
    written = f"{{nsdrake-figure}}`{number} µs <"
    for wrong in (f"{number + 1} µs", f"{number} ms", "0.1 ms"):
        changed = {page: text.replace(written, f"{{nsdrake-figure}}`{wrong} <", 1)}
        assert any(f"'{wrong}'" in p for p in figure_problems(changed)), wrong
    problem = nsdrake_docs.figure_problem
    assert problem(ROOT, "62.9 µm", "realism | clean | tangential_position_error_rms | m") is None
    assert "is not" in problem(ROOT, "63.9 µm", "realism | clean | tangential_position_error_rms | m")
    assert "unit" in problem(ROOT, "62.9 mm", "realism | clean | tangential_position_error_rms | µ")
    assert "is not in" in problem(ROOT, "3.2 ms", "machine_floor | run 5: | figure")
    assert "rows contain" in problem(ROOT, "1 ms", "machine_floor | cyclictest | figure")
    assert "does not exist" in problem(ROOT, "1", "no_such_family | a | b")


def test_a_ratio_a_prose_cell_and_a_small_figure_are_checked():
    """A ratio ``ROW ÷ ROW2`` is the two cells' quotient to the digits written (gear
    friction's tool error is 0.00773/6.291e-05 = 122.9 × the clean run's: '140' or '120',
    a rounding by eye, fails); a figure inside a prose cell is found there (and a figure
    the sentence does not hold is not); an e-notation figure is held to its own digits
    ('8.8e-13' is not '8.738e-13', which a tolerance of 0.05 in the mantissa's decimals
    let through)."""
    problem = nsdrake_docs.figure_problem
    ratio = "realism | gear friction ÷ clean | tangential_position_error_rms"
    assert problem(ROOT, "123", ratio) is None
    assert "is not 122.9" in problem(ROOT, "120", ratio)
    assert "a ratio is a bare number" in problem(ROOT, "123 m", ratio)
    assert "rows contain" in problem(ROOT, "1", "realism | gear friction ÷ no such row | en_rms")
    failed = "gradient_projection | Moore-Penrose | failed_at"
    assert problem(ROOT, "0.598 s", failed) is None and problem(ROOT, "73 N", failed) is None
    assert "is not in" in problem(ROOT, "0.6 s", failed)
    peak = "null_space_bandwidth | 80 rad/s / dyn. consistent PD (H) | task_disturbance_peak | m/s²"
    assert problem(ROOT, "8.74e-13 m/s²", peak) is None
    assert "is not" in problem(ROOT, "8.8e-13 m/s²", peak)


# A path: a top-level folder of the repository, then path characters. Template paths
# (FAMILY, NAME), globs and the outputs commands write (runs/, docs/_build) are not named
# files.
TOP = r"(?:nsdrake|docs|tests|scripts|bench|urdf|diagrams|\.ci)"
PATH = re.compile(rf"(?<![\w./-]){TOP}/[\w./-]*")
NOT_A_FILE = re.compile(r"[A-Z]{3,}|\*|_build|\{|<")


def named_paths(text: str) -> set[str]:
    """The repository paths a text names, trailing punctuation and ``::test``/``:name``
    suffixes cut."""
    found = set()
    for raw in PATH.findall(text):
        path = raw.rstrip(".,;:)")
        if path.count("/") and not NOT_A_FILE.search(path):
            found.add(path)
    return found


def docstrings() -> dict[str, str]:
    """Module path → its text (the API page renders the docstrings)."""
    return {p.relative_to(ROOT).as_posix(): p.read_text() for p in sorted((ROOT / "nsdrake").glob("**/*.py"))}


def missing_paths(texts: dict[str, str]) -> list[str]:
    return [
        f"{page}: names {path}, which does not exist"
        for page, text in texts.items()
        for path in sorted(named_paths(text))
        if not (ROOT / path).exists()
    ]


def test_every_path_a_page_names_exists():
    """Catches a page (or a docstring the API page shows) naming a file that was moved or
    never was (the API page named tests/docs/test_docs.py, a docstring nsdrake/priority.py)."""
    assert missing_paths({**pages(), **docstrings()}) == []


def test_a_missing_path_is_caught():
    """The path check finds a path in backticks, in prose, with a test suffix, and leaves
    templates and outputs alone."""
    text = (
        "see `tests/docs/test_docs.py::test_x`, nsdrake/priority.py. Also "
        "`docs/results/FAMILY/table.md`, docs/_build/html and `nsdrake/control/priority.py`."
    )
    assert named_paths(text) == {
        "tests/docs/test_docs.py",
        "nsdrake/priority.py",
        "nsdrake/control/priority.py",
    }
    assert missing_paths({"page": text}) == [
        "page: names nsdrake/priority.py, which does not exist",
        "page: names tests/docs/test_docs.py, which does not exist",
    ]


# --- a measured-looking figure written bare -------------------------------------------------


def checked_pages() -> dict[str, str]:
    """Every page held to it (issue 47): README.md, docs/**/*.md, the tutorials' markdown
    cells, and the prose of the result tables the commands write (docs/results/**/table.md:
    a family's description, a benchmark's set-up), which the site renders too."""
    out = pages()
    for table in sorted((ROOT / "docs" / "results").glob("**/table.md")):
        lines = table.read_text().splitlines()  # its rows are the command's figures: the prose alone
        out[table.relative_to(ROOT).as_posix()] = "\n".join(x for x in lines if not x.startswith("|"))
    return out


# A decimal figure with two significant digits or more, or one in e-notation, outside a
# role, code, a results table's copy and a math span: what a measurement looks like ('0.0114', '2.18',
# '9.7e-7'). Set-up values are mostly single digits or integers ('10 N', '0.5 rad', '125 Hz',
# '1000 N m/s'); a measured integer ('30 Hz') is therefore not caught.
NUMBER = re.compile(r"(?<![\w.\-/^])[−+-]?\d+(?:\.\d+)?(?:e[−-]?\d+)?(?![\w])")


def measured_looking(figure: str) -> bool:
    mantissa, _, exponent = figure.lstrip("+−-").partition("e")
    if exponent:
        return True
    return "." in mantissa and len(mantissa.replace(".", "").strip("0")) >= 2


# The bare figures each page may keep, with why each is not a measurement: a set-up value (a
# scenario's or a test's input, a tolerance, a version, a published limit) or a closed form.
# Per page: a figure set up on one page may be measured on another.
PYTHON = {"3.10": "the Python nsdrake needs, pyproject.toml's requires-python (a version)"}
SLOWEST_POLE = (
    "the rule's slowest pole on fig3, ω = 50 rad/s scaled by fig3's null-space inertias at its "
    "start (a closed form of the set-up; the table's own column holds it too)"
)
FIRST_STEP = (
    "the gradient family's first step, which tests/studies/test_gradient_projection_family.py "
    "holds to this text"
)
NOT_MEASURED: dict[str, dict[str, str]] = {
    "README.md": PYTHON,
    "docs/getting_started.md": PYTHON,
    "docs/laws.md": {
        "1.06": "3/(2√2), the paper's law's damping ratio under the rule (a closed form)",
        "0.92": "the factor of the delayed margin a test runs at (its choice)",
        "1.05": "the factor of the delayed margin a test runs at (its choice)",
        "2.3": "panda_self_motion's q_d moves from 2.3 s (the scenario's input)",
        "3.5": "the push's start time [s] (the family's input)",
    },
    "docs/claims.md": {
        "0.066": "σ √((1 − a)/(1 + a)) of the sensor's configured noise (a closed form)",
        "0.108": "the belt rung's configured rotor inertia per joint (an input)",
        # the realism rungs' table: each rung's defaults and the source of each
        "0.25": "the issue's 0.25–0.5 ms plant step, the physics rung's source (an input)",
        "1.6": "the torque joints 1–3 carry in fig3 pressing 10 N: the basis of the friction "
        "default τ_c, as nsdrake/realism/config.py states its choice",
        "2.9": "the torque joints 1–3 carry in fig3 pressing 10 N: the basis of the friction "
        "default τ_c, as nsdrake/realism/config.py states its choice",
        "3e-3": "the belt rung's rotor inertia I_m [kg m²] (its default)",
        "1e-4": "the lightest rotor inertia [kg m²] tried for the belt rung, a real servo's order (an input)",
        "1.94": FIRST_STEP,
        "1.96": FIRST_STEP,
    },
    "docs/architecture.md": {
        "1e-12": "the three ways' agreement tolerance, tests/control/test_three_ways.py's EXACT",
    },
    "docs/command_line.md": {
        "1.1": "YAML 1.1, a version of the format",
        "1.2": "YAML 1.2, a version of the format",
        "1e-3": "the start tests/control/test_singular.py runs the controller from (its input)",
        # the tables of settings nsdrake refuses and of the sweeps
        "2.175": "the Panda's published velocity limit of its slowest joints [rad/s]",
        "4.35e-3": "2 × 2.175 rad/s × 1 ms, the start tolerance's bound (a closed form)",
        "3.5": "the robustness sweep's duration [s] (its input)",
        "2.5": "CONTACT_OMEGA_T, the ω T a period is refused above (nsdrake/experiment/checks.py)",
        "2.2": "ω T of fig3's force loop at 10 ms, ω = √(K_p,n + K_f k_c) (a closed form)",
        "2.7": "ω T of fig3's force loop at 12 ms (a closed form)",
    },
    "docs/open_choices.md": {
        "1.5": "the tool sphere's radius [cm], urdf/panda.urdf and urdf/arm4.urdf (the set-up)",
        "1e-10": "the central differences' own error for h = 1e-5 (O(h⁴) + O(ε/h)), the order "
        "tests/control/test_criteria.py's docstring derives",
        "1e-5": "the order of GJK's witness-point error tests/station/test_panda_model.py states",
        "0.15": "touch_speed · stop_time / 2 = 3 mm/s · 0.1 s / 2, the stop's overtravel "
        "(a closed form tests/experiment/test_first_contact.py checks)",
        "0.015": "that overtravel through the normal spring, 0.15 mm · K_p_normal / K_f = 100 N/m "
        "(a closed form of the default gains)",
        "2.5": "panda_wipe's approach_speed [cm/s] (the scenario's input)",
    },
    "docs/own_diagram.md": {"1.5": "where the RMS window starts [s] (the benchmark's set-up)"},
    "docs/your_arm.md": {
        "0.61": "the lever arm [m] of the 1 kg at ur5_press's start pose: the pose's geometry",
    },
    "docs/tutorials/own_arm.ipynb": {
        "0.35": "the tutorial arm's link length [m] (its input)",
        "0.25": "the tutorial arm's link length [m] (its input)",
        "0.15": "the tutorial arm's link length [m] (its input)",
    },
    "docs/real_arm.md": {
        "1e-9": "two tests' tolerances: the drive against the direct run, the payload's torque",
        "37.5": "drake-franka-driver's k_d [N m s/rad], nsdrake/driver/serve.py's DAMPING",
        "3.75": "drake-franka-driver's k_d [N m s/rad], nsdrake/driver/serve.py's DAMPING",
        "2.5": "drake-franka-driver's k_d [N m s/rad], nsdrake/driver/serve.py's DAMPING",
        "1.9": "an example gap [periods] of the clock rule",
        "1e-4": "POSITION_NOISE [rad], the sensing noise the joint-step bound allows (a setting)",
        "2.48e-3": "(2.175 rad/s · 1.05) · 1 ms + 2 · 1e-4 rad, the joint-step bound (a closed form)",
        "2e-4": "twice POSITION_NOISE, the consistency bound's constant [rad] (nsdrake/driver/panda.py)",
        "1e-2": "VELOCITY_NOISE [rad/s], the consistency bound's velocity term (a setting)",
        "7.5": "the Panda's published joint acceleration limit [rad/s²], the smallest",
        "2.6e-4": "the consistency bound over one period (a closed form, nsdrake/driver/panda.py)",
        "7.9e-3": "the consistency bound over 50 periods, joint 2 (a closed form)",
        "1.6e-2": "the consistency bound over 50 periods, joints 6–7 (a closed form)",
        "0.063": "the pre-issue-43 bound over 50 periods at 100 rad/s² (a closed form)",
        "0.95": "the command success rate below which the timing line reports it (driver/timing.py)",
        "2.175": "the Panda's published velocity limit of its slowest joints [rad/s]",
        "4.35e-3": "2 × 2.175 rad/s × 1 ms, the start tolerance's bound (a closed form)",
        "5.3": "1/(2π · 30 Hz), the 30 Hz low-pass's time constant [ms] (a closed form)",
        "1.75": "the UDP test's drive duration [s] (its input)",
        "9.76": "the lower end of EARTH_GRAVITY [m/s²], nsdrake/driver/panda.py (Hirt et al. 2013, rounded)",
        "9.84": "the upper end of EARTH_GRAVITY [m/s²], nsdrake/driver/panda.py (Hirt et al. 2013, rounded)",
        "2.9": "3 kg less urdf/panda.urdf's 0.1 kg tool: the payload left under the rating (a closed form)",
        "0.73": "the Franka Hand's mass in example-robot-data's panda.urdf [kg] (the vendor's file)",
    },
    "docs/results/gradient_projection/table.md": {"1.94": FIRST_STEP},
    "docs/results/null_space_bandwidth/table.md": {
        "2.3": "panda_self_motion's q_d moves from 2.3 s (the scenario's input)",
    },
    "docs/results/plant_timing/table.md": {"1.5": "where the RMS window starts [s] (the set-up)"},
    **{
        f"docs/results/null_space_laws/{part}table.md": {"18.45": SLOWEST_POLE}
        for part in ("", "posture/", "push/", "task/")
    },
}

# The sections of a page that are a dated log of measurements taken by hand (each entry
# names its command, commit or date, and the machine's load): history, not a figure the
# page claims today, so not held to a table. The section's heading line → why it is a log;
# the section runs to the next heading of its level or above.
LOGS: dict[str, dict[str, str]] = {
    "docs/development.md": {
        "## The test suite's time": "each run with its command, commit or issue and load: a log of "
        "the suite's timings (an idle machine's timing is no results table's)",
    },
    "docs/architecture.md": {
        "## Measured by hand: a dated log": "the compile's and the tick's timings, each with its "
        "command, commit and load, as the section's first paragraph says",
    },
}

CODE = re.compile(r"`(?:[^`\n]|\n(?![ \t]*\n))*`")  # a code span, which may wrap but not cross a paragraph
MATH = re.compile(r"\$(?:[^$\n]|\n(?![ \t]*\n))*\$")
CITATION = re.compile(r"(?:Sections?|Eqs?\.) [\d.]+")


COPY = re.compile(r"^<!-- table: docs/results/[^ ]+/table\.md -->$")  # tests/test_results_tables.py's marker


def prose_lines(text: str, logs=()) -> list[str]:
    """The page's lines with fenced blocks, the sections headed by one of ``logs`` and the
    rows of a results table's copy (the table right after a ``<!-- table: … -->`` marker,
    which tests/test_results_tables.py holds equal to its file) blanked, the line count
    kept. A table written by hand is prose: its cells are checked like a sentence."""
    out, fenced, log_level, copy = [], False, 0, ""
    for line in text.splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
            out.append("")
            continue
        heading = re.match(r"(#+) ", line) if not fenced else None
        if heading and log_level and len(heading.group(1)) <= log_level:
            log_level = 0
        if heading and line.strip() in logs:
            log_level = len(heading.group(1))
        row = line.startswith("|")
        if COPY.match(line.strip()):
            copy = "marked"  # the next table is a copy
        elif row and copy:
            copy = "rows"
        elif copy == "rows" or (line.strip() and not row):
            copy = ""  # the copy ended (or the marker had no table)
        out.append("" if fenced or log_level or (row and copy) else line.replace("|", " | "))
    return out


def bare_figures(text: str, allowed=(), logs=()) -> list[str]:
    """The measured-looking figures of a page's prose that are not an nsdrake-figure, apart
    from the ``allowed`` set-up figures and the ``logs`` sections."""
    prose = "\n".join(prose_lines(text, logs))
    for span in (nsdrake_docs.FIGURE_ROLE, CODE, MATH, CITATION):
        prose = span.sub(" ", prose)
    return [f for f in NUMBER.findall(prose) if measured_looking(f) and f.lstrip("+−-") not in allowed]


CHECKED = checked_pages()


@pytest.mark.parametrize("page", sorted(CHECKED))
def test_no_measured_figure_is_written_bare(page):
    """Every measured figure of the page is an nsdrake-figure, so that regenerating its
    table flags it; what is left bare is a set-up figure this file names with its reason.
    Catches a figure copied from a table by hand (laws.md said '0.0048', '0.046 rad',
    '0.25–0.31 s'; claims.md '30 Hz, 2.5 N', '+0.79 N/s'), and a timing written into a page
    outside its dated log (architecture.md's compile and tick costs)."""
    assert bare_figures(CHECKED[page], NOT_MEASURED.get(page, {}), LOGS.get(page, {})) == []


def test_every_allowance_is_used_on_its_page():
    """Each allowed figure is still a bare figure of its page, and each log's heading is one
    of its page's headings: an allowance outlives neither its figure nor its section (a
    stale entry would let a measured figure of the same digits through later)."""
    assert set(NOT_MEASURED) <= set(CHECKED) and set(LOGS) <= set(CHECKED)
    for page, allowed in NOT_MEASURED.items():
        found = {f.lstrip("+−-") for f in bare_figures(CHECKED[page], (), LOGS.get(page, {}))}
        assert set(allowed) - found == set(), page
    for page, logs in LOGS.items():
        headings = {line.strip() for line in CHECKED[page].splitlines() if re.match(r"#+ ", line)}
        assert set(logs) - headings == set(), page


def test_a_bare_figure_is_found():
    """The check finds a measured figure written bare, in e-notation and as a ratio, and
    leaves roles, code (wrapped too), a results table's copy, math, single-digit set-up
    values, a page's allowed figures and its log sections alone; a table by hand is prose;
    a log section ends at the next heading of its level."""
    text = (
        "the error is 0.0048 rad (`0.0047`), 9.7e-7 predicted, × 2.2 the clean run's; "
        "{nsdrake-figure}`0.0114 <a | b | c>` and $0.25$ at 10 N, 0.5 rad, 1000 N m/s\n"
        "<!-- table: docs/results/a/table.md -->\n\n| 0.31 | a copy's row |\n```\n0.77\n```\n"
        "Section 3.4 and Eq. 2.1, `a code span\n"
        "wrapped: 8174.4`, Python 3.10\n\n## Log\n\n47.1 CPU-s\n\n### an entry\n\n79.0 s\n\n"
        "## Next\n\n64.1 CPU-s"
    )
    assert bare_figures(text) == ["0.0048", "9.7e-7", "2.2", "3.10", "47.1", "79.0", "64.1"]
    assert bare_figures(text, {"3.10": "a version"}, {"## Log": "a log"}) == [
        "0.0048",
        "9.7e-7",
        "2.2",
        "64.1",
    ]
    assert bare_figures("`an odd backtick\n\n0.0048 rad`") == ["0.0048"]  # no span across a paragraph
    # a table by hand is prose; a copy's marker covers the one table after it, not the next
    copy = "<!-- table: docs/results/a/table.md -->\n| a |\n|---|\n| 0.31 |\n\n| b |\n|---|\n| 0.42|\n"
    assert bare_figures(copy) == ["0.42"]
    assert bare_figures("<!-- table: docs/results/a/table.md -->\ntext\n\n| 0.31 |") == ["0.31"]
