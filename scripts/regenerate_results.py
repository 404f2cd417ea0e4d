"""Regenerates the committed result tables (docs/results/FAMILY/) and says which changed.

    python scripts/regenerate_results.py --family NAME|all [--runs DIR]

Each folder docs/results/FAMILY/ holds ``command``, the one line that made its table
(``nsdrake compare FAMILY [options]``, ``python bench/bench_FAMILY.py [options]`` for a
benchmark's table: this machine's figures, which another machine will not reproduce, or
``python scripts/FAMILY.py [options]`` for a page's own figures), and
``table.md``, the table that command wrote, unedited; the docs pages copy that table's rows
(a test checks the copy, tests/test_results_tables.py). This script re-runs the command of
the family named (or of every folder, with ``all``) with ``--out RUNS/FAMILY`` (and
``--overwrite`` for a compare; default RUNS: runs/results; the run folder with every
variant's traces is kept there), copies the new ``table.md`` over the committed one (and
the committed figures, ``*.png``, with the run's), and prints one
line per family: ``unchanged``, or ``changed`` with
the variants whose rows differ (then copy the rows into the page, and check its prose).

A family run is CPU-heavy (minutes per family): prefix ``nice`` on a shared machine.
``--runs`` relative is taken from the folder the script is run in (not the checkout's);
nothing is written outside RUNS and docs/results. The last line says how many families
were regenerated and the exit status, which agree: 0 if every command succeeded (changed
or not), 1 if one failed (its line says why), 2 for a family without a results folder.

Ctrl-C (SIGINT, to the script or to its process group from a terminal) stops it as
``nsdrake compare`` stops itself: the command under way gets one SIGINT (it runs in a
process group of its own, so a terminal's Ctrl-C reaches it only through this script,
once) and the time it takes to mark its folder interrupted and keep each finished
variant; the committed table of that family is left as it was (a family whose copy had
begun finishes it first), the families done before keep theirs, and the last line says
so and ``exit 130``; no traceback. The command is started with SIGINT ignored and the
signal is passed on once it has installed its own handler (read from
``/proc/PID/status``): a SIGINT while Python imports it would otherwise end it with a
KeyboardInterrupt traceback.
"""

from __future__ import annotations

import argparse
import shlex
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"


def result_families() -> list[str]:
    """The families with a committed results folder."""
    return sorted(p.parent.name for p in RESULTS.glob("*/command"))


def read_command(family: str) -> list[str]:
    """The command of docs/results/FAMILY/command, as arguments for this Python: a
    ``nsdrake compare FAMILY [options]``, or a benchmark ``python bench/bench_FAMILY.py
    [options]`` (a machine's measured figures), without an ``--out`` (this script chooses
    where it runs)."""
    path = RESULTS / family / "command"
    words = shlex.split(path.read_text())
    if any(w.startswith("--out") for w in words):
        raise SystemExit(f"{path}: must not name --out (this script chooses where the run goes)")
    if words[:3] == ["nsdrake", "compare", family]:
        return ["-m", "nsdrake", *words[1:]]
    if words[:2] in (["python", f"bench/bench_{family}.py"], ["python", f"scripts/{family}.py"]):
        return words[1:]
    forms = (
        f"'nsdrake compare {family} [options]', 'python bench/bench_{family}.py [options]' "
        f"or 'python scripts/{family}.py [options]'"
    )
    raise SystemExit(f"{path}: must read {forms}")


def table_rows(text: str) -> dict[str, str]:
    """A table.md's rows by their first cell (the variant), header and separator left out."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    return {line.split("|")[1].strip(): line for line in lines[2:]}


INTERRUPTED = 130  # exit status after Ctrl-C (128 + SIGINT), as nsdrake's commands exit
POLL = 0.02  # [s] how often the wait for a command looks whether a Ctrl-C is to be passed on


class CtrlC:
    """Ctrl-C for the script (module docstring): the handler only notes it; :meth:`run`
    passes it on to the command under way, once, when that command can take it."""

    def __init__(self):
        self.requested = False

    def handler(self, signum, frame) -> None:
        self.requested = True

    def run(self, argv: list[str]) -> int:
        """``argv`` run from the checkout, in a process group of its own with SIGINT ignored
        until it sets its own handler; its exit status."""
        child = subprocess.Popen(
            argv, cwd=ROOT, process_group=0, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)
        )
        passed_on = False
        while True:
            try:
                return child.wait(timeout=POLL)
            except subprocess.TimeoutExpired:
                pass
            if self.requested and not passed_on and takes_sigint(child.pid):
                child.send_signal(signal.SIGINT)
                passed_on = True


def takes_sigint(pid: int) -> bool:
    """Whether process ``pid`` no longer ignores SIGINT (its ``SigIgn`` mask in
    /proc/PID/status; where that cannot be read, True)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True
    for line in status.splitlines():
        if line.startswith("SigIgn:"):
            return not int(line.split()[1], 16) & (1 << (signal.SIGINT - 1))
    return True


def regenerate(family: str, runs: Path, ctrl_c: CtrlC) -> tuple[str, bool]:
    """Runs the family's command into runs/FAMILY and copies its table; (its line, ok)."""
    args = read_command(family)
    out = runs / family
    code = ctrl_c.run(
        [sys.executable, *args, "--out", str(out), *(["--overwrite"] if args[0] == "-m" else [])]
    )
    new = out / "table.md"
    if ctrl_c.requested and code != 0:
        return (
            f"{family}: interrupted (Ctrl-C; the command exited {code}); its run so far is in {out}/ "
            "(unfinished variants marked interrupted); the committed table is left as it was"
        ), False
    if code != 0:
        return f"{family}: FAILED (exit {code}); the committed table is left as it was", False
    if not new.exists():
        why = f"the command exited 0 but wrote no {new}"
        return f"{family}: FAILED ({why}); the committed table is left as it was", False
    committed = RESULTS / family / "table.md"
    old_text = committed.read_text() if committed.exists() else ""
    new_text = new.read_text()
    committed.write_text(new_text)
    nested = _copy_nested_tables(family, out)
    for image in (RESULTS / family).glob("*.png"):  # the figures a page shows, refreshed with it
        if (out / image.name).exists():
            image.write_bytes((out / image.name).read_bytes())
    also = f"; also wrote {', '.join(nested)} (copy their rows into the page)" if nested else ""
    if new_text == old_text:
        return f"{family}: unchanged{also}", True
    old, now = table_rows(old_text), table_rows(new_text)
    differ = [name for name in now if old.get(name) != now[name]] + [n for n in old if n not in now]
    what = "; rows: " + ", ".join(differ) if differ else " (header or description only)"
    return f"{family}: changed{what}{also}", True


def _copy_nested_tables(family: str, out: Path) -> list[str]:
    """The further tables one command wrote beside its own (``out/NAME/table.md``, e.g.
    bench_drive.py's filter/ and soak/), copied to docs/results/FAMILY/NAME/table.md; their
    paths."""
    copied = []
    for table in sorted(out.glob("*/table.md")):
        target = RESULTS / family / table.parent.name / "table.md"
        target.parent.mkdir(exist_ok=True)
        target.write_text(table.read_text())
        copied.append(target.relative_to(ROOT).as_posix())
    return copied


def main() -> int:
    ctrl_c = CtrlC()
    previous = signal.signal(signal.SIGINT, ctrl_c.handler)  # first: from here on noted, never raised
    try:
        return _main(ctrl_c)
    finally:
        signal.signal(signal.SIGINT, previous)


def _main(ctrl_c: CtrlC) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--family", required=True, help="a family with a docs/results folder, or all")
    parser.add_argument(
        "--runs",
        type=Path,
        default=ROOT / "runs" / "results",
        help="where the runs are kept (a relative path is from the folder the script is run in)",
    )
    args = parser.parse_args()
    runs = args.runs.expanduser().resolve()  # from where the script is run, not the checkout it runs in
    known = result_families()
    if args.family != "all" and args.family not in known:
        print(
            f"--family: no docs/results/{args.family}/command; the families with results: "
            f"{', '.join(known)}; exit 2"
        )
        return 2
    if ctrl_c.requested:  # before any command ran
        print(f"interrupted (Ctrl-C): 0 regenerated; exit {INTERRUPTED}")
        return INTERRUPTED
    lines, ok = [], True
    families = known if args.family == "all" else [args.family]
    for family in families:
        line, good = regenerate(family, runs, ctrl_c)
        lines.append(line)
        ok &= good
        if ctrl_c.requested:
            break
    if ctrl_c.requested:
        done = sum(1 for line in lines if ": unchanged" in line or ": changed" in line)
        left = len(families) - len(lines)
        lines.append(
            f"interrupted (Ctrl-C): {done} of {len(families)} regenerated"
            + (f", {left} not started" if left else "")
            + f"; exit {INTERRUPTED}"
        )
        print("\n".join(lines), flush=True)
        return INTERRUPTED
    failed = sum(1 for line in lines if ": FAILED" in line)
    lines.append(
        f"{len(lines) - failed} of {len(lines)} regenerated; exit 0"
        if ok
        else f"{failed} of {len(lines)} FAILED; exit 1"
    )
    print("\n".join(lines))
    return 0 if ok else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:  # a Ctrl-C while Python started the script, before main's handler
        print(f"interrupted (Ctrl-C) before anything ran; exit {INTERRUPTED}")
        sys.exit(INTERRUPTED)
