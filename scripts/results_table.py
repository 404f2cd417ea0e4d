"""The command line every ``scripts/*.py`` that writes one results table shares:
``--out FOLDER``, the table written to FOLDER/table.md (docs/results/<name>/ when
regenerating the committed copy: scripts/regenerate_results.py)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path


def table_main(doc: str, table: Callable[[], str]) -> int:
    """Parses ``--out``, writes ``table()`` into its table.md and says where; ``doc``: the
    script's docstring, whose first line describes the command."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="the folder to write table.md into")
    args = parser.parse_args()
    text = table()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(text)
    print(f"wrote {args.out / 'table.md'}")
    return 0
