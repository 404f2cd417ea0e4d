"""The README is the project's front page (issue 26): short, with the Quick start's two
commands exactly as they are run from a fresh clone, and links into the documentation
that all resolve."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()

QUICK_START = (
    "python3 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/nsdrake run fig3",
    "python3 -m venv .venv && .venv/bin/pip install -e '.[test,cluster]' && .venv/bin/pytest",
)


def test_the_readme_is_a_front_page_with_the_quick_start_commands():
    """At most 200 lines, and each Quick start command on a line of its own in a bash block.
    Catches the README growing back into the manual, or a Quick start command edited."""
    assert len(README.splitlines()) <= 200
    blocks = re.findall(r"```bash\n(.*?)```", README, flags=re.S)
    for command in QUICK_START:
        assert any(command in block.splitlines() for block in blocks), command


def test_every_relative_link_and_image_of_the_readme_exists():
    """Each relative link (a page, the notebook, the Fig. 3 image) names a file in the
    repository, and a link to a heading names one the page has (GitHub's anchors: lower
    case, punctuation dropped, spaces as hyphens). Catches a page renamed or moved."""
    targets = re.findall(r"\]\(([^)\s]+)\)", README)
    relative = [t for t in targets if not re.match(r"[a-z]+://", t)]
    assert any(t.endswith("fig3.png") for t in relative)
    for target in relative:
        path, _, anchor = target.partition("#")
        assert (ROOT / path).is_file(), target
        if anchor:
            headings = re.findall(r"^#+ (.*)$", (ROOT / path).read_text(), flags=re.M)
            slugs = {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}
            assert anchor in slugs, target
