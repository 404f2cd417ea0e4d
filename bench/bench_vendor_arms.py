"""Every fixed-base arm of example-robot-data (PyPI), loaded as shipped, holds its tool's
pose for 1 s in closed loop against Drake's own plant of its file
(nsdrake/studies/vendor_arms.py says how). Writes ``table.md`` under ``--out`` (default
docs/results/vendor_arms/); needs ``pip install 'nsdrake[arms]'``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nsdrake.studies import vendor_arms

OUT = Path(__file__).resolve().parents[1] / "docs" / "results" / "vendor_arms"
TITLE = """# vendor_arms

Every fixed-base arm description of example-robot-data, untouched, holding its tool for 1 s
against Drake's own plant of the same file while the null space moves the joints (largest
errors over the second). The controller's model compensates a file's joint damping D as D q̇
and as the inertia h D it adds over the plant's implicit step h (damping_time = h); "the
damping as D q̇ only": without that inertia (damping_time 0; – for a file without damping);
"without the file's damping": removed from the plant and the model both.

"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=OUT, help="where table.md is written")
    args = parser.parse_args()
    if vendor_arms.robots_folder() is None:
        print(
            f"bench_vendor_arms: {vendor_arms.PACKAGE} is not installed: {vendor_arms.INSTALL}",
            file=sys.stderr,
        )
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(TITLE + vendor_arms.table())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
