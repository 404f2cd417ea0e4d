"""Mutation testing (issue 37, item 4; not run in CI): one-line mistakes of the kinds a
competent developer makes (a comparison's boundary, which end of a queue, an off-by-one,
a dropped unit factor, a state not restored), applied one at a time to the sources, each
followed by the given tests; a mutant the tests let through is listed with its line.
Prints one line per mutant and the score (killed / mutants) at the end, and writes them
as JSON with ``--out``.

    .venv/bin/python scripts/mutate.py nsdrake/driver --list
    .venv/bin/python scripts/mutate.py nsdrake/driver --sample 30 --seed 1 --tests tests/driver

The sources are mutated in place and restored after each mutant (also on Ctrl-C or a
kill): run it in a worktree of your own with nothing uncommitted under the mutated
folder, on a quiet machine. Each mutant's tests run with ``-x -n 0`` (the first failure
is enough) and ``--timeout`` seconds at most: a mutant whose tests time out counts as
killed and says so (a hang is a failure), so first run the tests once unmutated, warm
(numba compiles the kernels of a fresh checkout), to know their time.
"""

from __future__ import annotations

import argparse
import ast
import json
import random
import re
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# (name, pattern, replacement): each match on a code line is one mutant
OPERATORS = [
    ("boundary >= to >", r"(?<![<>=!])>=(?!=)", ">"),
    ("boundary > to >=", r"(?<![<>=!-])>(?![=>])", ">="),
    ("boundary <= to <", r"(?<![<>=!])<=(?!=)", "<"),
    ("boundary < to <=", r"(?<![<>=!])<(?![=<])", "<="),
    ("newest to oldest", r"\[-1\]", "[0]"),
    ("oldest to newest", r"\[0\]", "[-1]"),
    ("keep the first instead of the last", r"\[:-(\w+)\]", r"[\1:]"),
    ("off by one: + 1 dropped", r" \+ 1(?![\w.])", ""),
    ("off by one: - 1 dropped", r" - 1(?![\w.])", ""),
    ("unit: 2π dropped", r"2\.0 \* math\.pi \* ", ""),
    ("unit: * 1e6 dropped", r" \* 1e6\b", ""),
    ("unit: * 1e-3 dropped", r" \* 1e-3\b", ""),
    ("unit: * self.period dropped", r" \* self\.period\b", ""),
    ("min to max", r"\bmin\(", "max("),
    ("max to min", r"\bmax\(", "min("),
    ("and to or", r" and ", " or "),
]
# whole statements dropped: a state restored, a capacity set, a check made
DROPPED = re.compile(
    r"^\s*(gc\.unfreeze\(\)|gc\.enable\(\)|\w+\.set_queue_capacity\(.*\)|self\._check_stop\(\))\s*$"
)


@dataclass
class Mutant:
    path: str
    line: int
    operator: str
    before: str
    after: str
    killed: bool | None = None
    how: str = ""  # the first failing test, "timeout", or "" (survived)


def code_lines(source: str) -> set[int]:
    """Line numbers (1-based) that hold code, not docstrings or comments."""
    tree = ast.parse(source)
    docstrings = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            value = body[0].value
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                docstrings.update(range(body[0].lineno, body[0].end_lineno + 1))
    lines = source.splitlines()
    return {
        k
        for k, text in enumerate(lines, 1)
        if k not in docstrings and text.strip() and not text.strip().startswith(("#", "import", "from"))
    }


def mutants_of(path: Path) -> list[Mutant]:
    source = path.read_text()
    lines = source.splitlines()
    out = []
    for k in sorted(code_lines(source)):
        text = lines[k - 1].split("  #")[0]
        if '"' in text or "'" in text:  # strings (messages) hold words like "> 0": skip those lines
            continue
        if DROPPED.match(text):
            out.append(Mutant(str(path.relative_to(ROOT)), k, "statement dropped", text.strip(), "pass"))
        for name, pattern, replacement in OPERATORS:
            for match in re.finditer(pattern, text):
                after = text[: match.start()] + match.expand(replacement) + text[match.end() :]
                out.append(Mutant(str(path.relative_to(ROOT)), k, name, text.strip(), after.strip()))
    return out


def apply(mutant: Mutant) -> str:
    """Writes the mutant into its file; returns the original source."""
    path = ROOT / mutant.path
    source = path.read_text()
    lines = source.splitlines(keepends=True)
    line = lines[mutant.line - 1]
    indent = line[: len(line) - len(line.lstrip())]
    body = mutant.after if mutant.operator != "statement dropped" else "pass"
    comment = line[len(line.rstrip("\n")) :]
    lines[mutant.line - 1] = indent + body + comment
    path.write_text("".join(lines))
    return source


def run_tests(tests: list[str], timeout: float) -> tuple[bool, str]:
    command = [sys.executable, "-m", "pytest", "-x", "-q", "-n", "0", "-p", "no:cacheprovider", *tests]
    try:
        result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return True, "timeout"
    failed = [
        line.split(" ")[1] for line in result.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))
    ]
    return result.returncode != 0, (
        failed[0] if failed else f"exit {result.returncode}"
    ) if result.returncode else ""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", help="source folders or files to mutate (e.g. nsdrake/driver)")
    parser.add_argument("--tests", nargs="+", default=[], help="pytest arguments: files, folders")
    parser.add_argument("-m", dest="marker", default="not slow", help='pytest marker expression ("not slow")')
    parser.add_argument(
        "--sample", type=int, default=0, help="run this many mutants, drawn at random (0: all)"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per mutant's tests")
    parser.add_argument("--list", action="store_true", help="list the mutants and stop")
    parser.add_argument("--out", type=Path, help="write the mutants and the score as JSON here")
    args = parser.parse_args(argv)
    files = sorted(
        p
        for folder in args.folders
        for p in ([ROOT / folder] if folder.endswith(".py") else (ROOT / folder).rglob("*.py"))
    )
    mutants = [m for path in files for m in mutants_of(path)]
    if args.sample and args.sample < len(mutants):
        mutants = sorted(
            random.Random(args.seed).sample(mutants, args.sample), key=lambda m: (m.path, m.line)
        )
    if args.list:
        for m in mutants:
            print(f"{m.path}:{m.line} {m.operator}: {m.after}")
        print(f"{len(mutants)} mutants")
        return 0
    if not args.tests:
        parser.error("--tests: which tests run on each mutant (e.g. --tests tests/driver)")
    tests = [*args.tests, "-m", args.marker]
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # a kill restores the source too (finally)
    start = time.monotonic()
    for k, mutant in enumerate(mutants, 1):
        original = apply(mutant)
        try:
            mutant.killed, mutant.how = run_tests(tests, args.timeout)
        finally:
            (ROOT / mutant.path).write_text(original)
        word = f"killed by {mutant.how}" if mutant.killed else "SURVIVED"
        print(
            f"[{k}/{len(mutants)}] {mutant.path}:{mutant.line} {mutant.operator}: {mutant.after}  -> {word}",
            flush=True,
        )
    killed = sum(bool(m.killed) for m in mutants)
    score = {"mutants": len(mutants), "killed": killed, "seconds": round(time.monotonic() - start, 1)}
    print(f"score: {killed}/{len(mutants)} killed ({100 * killed / max(1, len(mutants)):.0f}%)")
    if args.out:
        args.out.write_text(
            json.dumps({"score": score, "mutants": [asdict(m) for m in mutants]}, indent=2) + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
