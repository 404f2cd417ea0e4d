"""Regenerates the committed result tables (docs/results/FAMILY/) and says which changed.

    python scripts/regenerate_results.py --family NAME|all [--runs DIR]

Each folder docs/results/FAMILY/ holds ``command``, the one line that made its table
(``nsdrake compare FAMILY [options]``), and ``table.md``, the table that command wrote,
unedited; the docs pages copy that table's rows (a test checks the copy,
tests/test_results_tables.py). This script re-runs the command of the family named (or of
every folder, with ``all``) with ``--out RUNS/FAMILY --overwrite`` (default RUNS: runs/results;
the run folder with every variant's traces is kept there), copies the new ``table.md``
over the committed one (and the committed figures, ``*.png``, with the run's), and prints one
line per family: ``unchanged``, or ``changed`` with
the variants whose rows differ (then copy the rows into the page, and check its prose).

A family run is CPU-heavy (minutes per family): prefix ``nice`` on a shared machine.
Exit status: 0 if every command succeeded (changed or not), 1 if one failed, 2 for a
family without a results folder.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"


def result_families() -> list[str]:
    """The families with a committed results folder."""
    return sorted(p.parent.name for p in RESULTS.glob("*/command"))


def read_command(family: str) -> list[str]:
    """The arguments of docs/results/FAMILY/command after ``nsdrake``, checked to be a
    ``compare`` of that family without an ``--out`` (this script chooses where it runs)."""
    path = RESULTS / family / "command"
    words = shlex.split(path.read_text())
    if words[:3] != ["nsdrake", "compare", family] or any(w.startswith("--out") for w in words):
        raise SystemExit(f"{path}: must read 'nsdrake compare {family} [options]' without --out")
    return words[1:]


def table_rows(text: str) -> dict[str, str]:
    """A table.md's rows by their first cell (the variant), header and separator left out."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    return {line.split("|")[1].strip(): line for line in lines[2:]}


def regenerate(family: str, runs: Path) -> tuple[str, bool]:
    """Runs the family's command into runs/FAMILY and copies its table; (its line, ok)."""
    args = read_command(family)
    out = runs / family
    done = subprocess.run(
        [sys.executable, "-m", "nsdrake", *args, "--out", str(out), "--overwrite"], cwd=ROOT
    )
    new = out / "table.md"
    if done.returncode != 0 or not new.exists():
        return f"{family}: FAILED (exit {done.returncode}); the committed table is left as it was", False
    committed = RESULTS / family / "table.md"
    old_text = committed.read_text() if committed.exists() else ""
    new_text = new.read_text()
    committed.write_text(new_text)
    for image in (RESULTS / family).glob("*.png"):  # the figures a page shows, refreshed with it
        if (out / image.name).exists():
            image.write_bytes((out / image.name).read_bytes())
    if new_text == old_text:
        return f"{family}: unchanged", True
    old, now = table_rows(old_text), table_rows(new_text)
    differ = [name for name in now if old.get(name) != now[name]] + [n for n in old if n not in now]
    what = "; rows: " + ", ".join(differ) if differ else " (header or description only)"
    return f"{family}: changed{what}", True


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--family", required=True, help="a family with a docs/results folder, or all")
    parser.add_argument(
        "--runs", type=Path, default=ROOT / "runs" / "results", help="where the runs are kept"
    )
    args = parser.parse_args()
    known = result_families()
    if args.family != "all" and args.family not in known:
        print(
            f"--family: no docs/results/{args.family}/command; the families with results: {', '.join(known)}"
        )
        return 2
    lines, ok = [], True
    for family in known if args.family == "all" else [args.family]:
        line, good = regenerate(family, args.runs)
        lines.append(line)
        ok &= good
    print("\n".join(lines))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
