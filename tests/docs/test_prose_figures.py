"""The docs' prose against the files behind it (issue 38), reading files only (no build, no
simulation):

- a figure written ``{nsdrake-figure}`162 µs <drive | loop alone | CPU p99.9>``` is
  the cell of docs/results/drive/table.md it names (docs/_ext/nsdrake_docs.py's
  ``figure_problem``, which the site's build runs too: a figure that differs is an error
  under ``sphinx-build -W``);
- every repository path a page names (README.md, docs/**/*.md, the tutorials' markdown
  cells, and the docstrings of nsdrake/, which the API page renders) exists.
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

# The pages whose prose is held to it (the referee's pages, issue 45); the others still
# state benchmark timings and set-up figures by hand (docs/development.md, "The result
# tables").
CHECKED_PAGES = ("docs/laws.md", "docs/claims.md")
# A decimal figure with two significant digits or more, or one in e-notation, outside a
# role, code, a table row and a math span: what a measurement looks like ('0.0114', '2.18',
# '9.7e-7'). Set-up values are mostly single digits or integers ('10 N', '0.5 rad', '125 Hz',
# '1000 N m/s'); a measured integer ('30 Hz') is therefore not caught.
NUMBER = re.compile(r"(?<![\w.\-/^])[−+-]?\d+(?:\.\d+)?(?:e[−-]?\d+)?(?![\w])")


def measured_looking(figure: str) -> bool:
    mantissa, _, exponent = figure.lstrip("+−-").partition("e")
    if exponent:
        return True
    return "." in mantissa and len(mantissa.replace(".", "").strip("0")) >= 2


# The bare figures these pages may keep, each with why it is not a measurement.
NOT_MEASURED = {
    "1.06": "3/(2√2), the paper's law's damping ratio under the rule (a closed form)",
    "0.92": "the factor of the delayed margin a test runs at (its choice)",
    "1.05": "the factor of the delayed margin a test runs at (its choice)",
    "2.3": "panda_self_motion's q_d moves from 2.3 s (the scenario's input)",
    "3.5": "the push's start time [s] (the family's input)",
    "0.066": "σ √((1 − a)/(1 + a)) of the sensor's configured noise (a closed form)",
    "0.108": "the belt rung's configured rotor inertia per joint (an input)",
    "1.94": "the gradient family's first step, tests/studies/test_gradient_projection_family.py",
    "1.96": "the gradient family's first step, tests/studies/test_gradient_projection_family.py",
}


def bare_figures(text: str) -> list[str]:
    """The measured-looking figures of a page's prose that are not an nsdrake-figure."""
    found, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
            continue
        if fenced or line.startswith("|"):
            continue
        prose = re.sub(
            r"`[^`]*`|\$[^$]*\$|(?:Sections?|Eqs?\.) [\d.]+", " ", nsdrake_docs.FIGURE_ROLE.sub(" ", line)
        )
        found += [
            f for f in NUMBER.findall(prose) if measured_looking(f) and f.lstrip("+−-") not in NOT_MEASURED
        ]
    return found


@pytest.mark.parametrize("page", CHECKED_PAGES)
def test_no_measured_figure_is_written_bare(page):
    """Every measured figure of the page is an nsdrake-figure, so that regenerating its
    table flags it. Catches a figure copied from a table by hand (laws.md said '0.0048',
    '0.046 rad', '0.25–0.31 s'; claims.md '30 Hz, 2.5 N', '+0.79 N/s')."""
    assert bare_figures((ROOT / page).read_text()) == []


def test_a_bare_figure_is_found():
    """The check finds a measured figure written bare, in e-notation and as a ratio, and
    leaves roles, code, tables, math and single-digit set-up values alone."""
    text = (
        "the error is 0.0048 rad (`0.0047`), 9.7e-7 predicted, × 2.2 the clean run's; "
        "{nsdrake-figure}`0.0114 <a | b | c>` and $0.25$ at 10 N, 0.5 rad, 1000 N m/s\n"
        "| 0.31 | a row |\n```\n0.77\n```\nSection 3.4 and Eq. 2.1"
    )
    assert bare_figures(text) == ["0.0048", "9.7e-7", "2.2"]
