"""Every result table in the README and the docs pages is the table a command wrote (issue 25).

docs/results/FAMILY/ holds ``command`` (``nsdrake compare FAMILY …``) and the ``table.md``
it wrote, unedited (scripts/regenerate_results.py re-runs the command and reports which
tables changed). The built site renders that file (the ``nsdrake-results`` directive); the
page's source (what GitHub shows) copies its rows after a marker line
``<!-- table: docs/results/FAMILY/table.md -->``. These tests read files only (no
simulation): they fail when a copy differs from its file by one character, when a marker
names a missing file, and when a results folder's table is copied nowhere.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))]
MARKER = re.compile(r"^<!-- table: (docs/results/[^ ]+/table\.md) -->$")


def table_lines(text: str) -> list[str]:
    """The lines of the first markdown table in ``text`` (header, separator, rows)."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith("|")), len(lines))
    end = start
    while end < len(lines) and lines[end].startswith("|"):
        end += 1
    return lines[start:end]


def readme_copies(readme: str) -> list[tuple[str, list[str]]]:
    """(marker path, the table lines right after the marker), for every marker: a table
    copied into two pages is two copies, each checked (a dict kept only the last page's)."""
    lines = readme.splitlines()
    copies = []
    for i, line in enumerate(lines):
        m = MARKER.match(line)
        if m:
            copy = (
                table_lines("\n".join(lines[i + 1 :]))
                if lines[i + 1 : i + 2] and lines[i + 1].startswith("|")
                else []
            )
            copies.append((m.group(1), copy))
    return copies


def differences(readme: str, root: Path) -> list[str]:
    """One line per copied table that is not its file's table, or per file not copied."""
    problems = []
    copies = readme_copies(readme)
    for path, copy in copies:
        file = root / path
        if not file.exists():
            problems.append(f"{path}: a page names it, but it does not exist")
            continue
        expected = table_lines(file.read_text())
        if copy != expected:
            first = next(
                (k for k, (a, b) in enumerate(zip(copy, expected, strict=False)) if a != b),
                min(len(copy), len(expected)),
            )
            problems.append(f"{path}: the page's copy differs from line {first + 1} of its table")
    for file in sorted((root / "docs" / "results").glob("**/table.md")):  # drive/filter/ too
        path = file.relative_to(root).as_posix()
        if path not in {p for p, _ in copies}:
            problems.append(f"{path}: not copied into any page (no marker)")
    return problems


def pages_text() -> str:
    """README.md and the docs pages, one after the other."""
    return "\n".join((ROOT / page).read_text() for page in PAGES)


def test_every_copied_table_is_its_file():
    """The copies in README.md and docs/*.md against docs/results/*/table.md, line by line.
    Catches a table edited in a page only, or regenerated without copying it over."""
    assert differences(pages_text(), ROOT) == []


def test_a_changed_digit_is_caught():
    """The check itself fails on pages whose copy differs by one digit, and on pages that
    leave a results table out: it is not a test that cannot fail."""
    readme = pages_text()
    path = readme_copies(readme)[0][0]
    row = table_lines((ROOT / path).read_text())[2]
    changed = row.replace("0", "9", 1) if "0" in row else row + " x"
    found = differences(readme.replace(row, changed, 1), ROOT)
    assert found[0].startswith(f"{path}: the page's copy differs")
    dropped = readme.replace(f"<!-- table: {path} -->", "", 1)
    assert f"{path}: not copied into any page (no marker)" in differences(dropped, ROOT)


def test_a_table_copied_into_two_pages_is_checked_in_both():
    """A second, stale copy of a table (docs/own_diagram.md kept the vendor table's older
    columns while your_arm.md's copy was current) is caught, whichever page comes first."""
    path = "docs/results/vendor_arms/table.md"
    table = "\n".join(table_lines((ROOT / path).read_text()))
    stale = table.replace("|---|", "|---|---|", 1)
    for first, second in ((table, stale), (stale, table)):
        pages = f"<!-- table: {path} -->\n{first}\n\ntext\n\n<!-- table: {path} -->\n{second}\n"
        found = [line for line in differences(pages, ROOT) if line.startswith(path)]
        assert found == [f"{path}: the page's copy differs from line 2 of its table"]


@pytest.mark.parametrize("folder", sorted(p.name for p in (ROOT / "docs" / "results").glob("*/")))
def test_every_results_folder_names_its_command(folder):
    """Each results folder's ``command`` is ``nsdrake compare FOLDER …``,
    ``python bench/bench_FOLDER.py …`` or ``python scripts/FOLDER.py …`` (the script re-runs
    it), and its table's title is that family."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from regenerate_results import read_command
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    assert read_command(folder)[:4] == ["-m", "nsdrake", "compare", folder] or read_command(folder)[:1] in (
        [f"bench/bench_{folder}.py"],
        [f"scripts/{folder}.py"],
    )
    assert (ROOT / "docs" / "results" / folder / "table.md").read_text().startswith(f"# {folder}\n")


def test_the_regenerate_script_refuses_an_unknown_family():
    """``--family`` names a folder with a command, or ``all``: anything else is one line, exit 2."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "regenerate_results.py"), "--family", "no_such_family"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2
    assert done.stdout.startswith("--family: no docs/results/no_such_family/command")


def test_the_regenerate_script_writes_a_relative_runs_folder_where_it_is_run(tmp_path, monkeypatch):
    """``--runs REL`` from another folder: the run goes to that folder's REL (it went into
    the checkout, then the script looked for the table where it is run, printed "FAILED
    (exit 0)" and exited 1 although the run had succeeded), the committed table is
    refreshed, nothing is written in the checkout, and the last line agrees with the exit
    status. A stand-in family whose command writes a table, so no simulation runs."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import regenerate_results as script
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    results = tmp_path / "docs" / "results"
    (results / "standin").mkdir(parents=True)
    (results / "standin" / "command").write_text("nsdrake compare standin\n")
    (results / "standin" / "table.md").write_text("# standin\n| variant | x |\n| - | - |\n| a | 1 |\n")
    writes = (
        "import pathlib, sys; out = pathlib.Path(sys.argv[sys.argv.index('--out') + 1]); "
        "out.mkdir(parents=True); "
        "(out / 'table.md').write_text('# standin\\n| variant | x |\\n| - | - |\\n| a | 2 |\\n')"
    )
    monkeypatch.setattr(script, "RESULTS", results)
    monkeypatch.setattr(script, "read_command", lambda family: ["-c", writes])
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    relative = f"runs-{tmp_path.name}"
    monkeypatch.setattr(sys, "argv", ["regenerate_results.py", "--family", "standin", "--runs", relative])
    lines = []
    monkeypatch.setattr("builtins.print", lambda text="": lines.extend(str(text).splitlines()))
    try:
        code = script.main()
        assert not (ROOT / relative).exists()  # nothing in the checkout
    finally:
        if (ROOT / relative).exists():
            import shutil

            shutil.rmtree(ROOT / relative)
    assert (elsewhere / relative / "standin" / "table.md").exists()
    assert "| a | 2 |" in (results / "standin" / "table.md").read_text()
    assert code == 0 and lines == ["standin: changed; rows: a", "1 of 1 regenerated; exit 0"], (code, lines)


def test_the_regenerate_scripts_last_line_says_a_failure_and_its_exit_status(tmp_path, monkeypatch):
    """A command that exits 0 without writing its table is a failure: its line says so
    (not "FAILED (exit 0)"), the last line says exit 1, and main returns 1."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import regenerate_results as script
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    results = tmp_path / "results"
    (results / "standin").mkdir(parents=True)
    (results / "standin" / "command").write_text("nsdrake compare standin\n")
    monkeypatch.setattr(script, "RESULTS", results)
    monkeypatch.setattr(script, "read_command", lambda family: ["-c", "pass"])
    monkeypatch.setattr(
        sys, "argv", ["regenerate_results.py", "--family", "standin", "--runs", str(tmp_path / "runs")]
    )
    lines = []
    monkeypatch.setattr("builtins.print", lambda text="": lines.extend(str(text).splitlines()))
    assert script.main() == 1
    assert lines[0].startswith("standin: FAILED (the command exited 0 but wrote no "), lines
    assert lines[-1] == "1 of 1 FAILED; exit 1", lines


def test_a_further_table_a_command_wrote_is_checked_too(tmp_path):
    """A table in a results folder's subfolder (bench_drive.py's filter/ and soak/, which
    docs/results/drive/command writes beside its own) must be copied into a page like any
    other: left out, or copied with a digit changed, it is caught. Catches a check that
    looks one folder deep only."""
    nested = tmp_path / "docs" / "results" / "drive" / "filter" / "table.md"
    nested.parent.mkdir(parents=True)
    nested.write_text("# filter\n\n| low-pass | force error |\n|---|---|\n| 30 Hz | 11.101 N |\n")
    assert differences("no table here\n", tmp_path) == [
        "docs/results/drive/filter/table.md: not copied into any page (no marker)"
    ]
    page = "<!-- table: docs/results/drive/filter/table.md -->\n| low-pass | force error |\n|---|---|\n"
    assert differences(page + "| 30 Hz | 11.101 N |\n", tmp_path) == []
    assert differences(page + "| 30 Hz | 11.109 N |\n", tmp_path)[0].endswith(
        "differs from line 3 of its table"
    )
