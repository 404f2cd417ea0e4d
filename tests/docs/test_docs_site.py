"""The documentation site's generated reference (docs/_ext/nsdrake_docs.py, docs/api.md):
it covers every exported name, every controller port and every scenario field, so the
built site cannot silently leave one out. ``sphinx-build -W`` in .ci/run builds it."""

from __future__ import annotations

import dataclasses
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

pytest.importorskip("sphinx", reason="the docs extra (pip install -e '.[docs]') is not installed")

import nsdrake  # noqa: E402
from nsdrake.control.controller import INPUTS, OUTPUTS  # noqa: E402
from nsdrake.experiment.scenario import Scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
import nsdrake_docs  # noqa: E402


def test_every_exported_name_has_an_api_entry():
    """docs/api.md documents every name of ``nsdrake.__all__`` (and StepResult, what
    ControllerStep returns). Catches a name exported without a reference entry."""
    api = (ROOT / "docs" / "api.md").read_text()
    documented = set(re.findall(r"\.\. auto(?:class|exception):: ([\w.]+)", api))
    for name in nsdrake.__all__:
        assert f"nsdrake.{name}" in documented, name
    assert "nsdrake.control.StepResult" in documented


def test_the_port_table_reads_every_port_of_the_controller():
    """Each input and output the controller exports has a line ``- ``name`` (size) [unit]:
    meaning`` in its docstring, read as such, with the units the README's table gave.
    Catches a port added without its line, or a parser that gives one port another's unit."""
    rows = nsdrake_docs.port_rows(nsdrake.NullSpaceImpedanceController.__doc__)
    assert set(rows["in"]) == set(INPUTS)
    assert set(rows["out"]) == set(OUTPUTS)
    assert rows["in"]["estimated_state"][:2] == ("2n", "rad, rad/s")
    assert [rows["in"][p][1] for p in ("desired_position", "desired_velocity", "desired_acceleration")] == [
        "m",
        "m/s",
        "m/s²",
    ]
    assert rows["in"]["desired_angular_acceleration"][:2] == ("3", "rad/s²")
    assert rows["out"]["generalized_force"][:2] == ("n", "N m")
    assert rows["out"]["manipulability"][:2] == ("1", "m²")
    assert rows["out"]["mode"][1] == ""  # [-]: no unit
    assert all(meaning for kind in rows.values() for _, _, meaning in kind.values())


def walk(cls, prefix=""):
    for doc in nsdrake_docs.field_docs(cls):
        yield prefix + doc.name, doc
        if doc.nested is not None:
            yield from walk(doc.nested, f"{prefix}{doc.name}.")


def test_every_scenario_field_has_a_comment():
    """Every leaf field of the scenario tree has a meaning or a unit from its comment, as
    the field reference renders it. Catches a field added without its comment (the site's
    build warns too, and -W makes that an error)."""
    fields = dict(walk(Scenario))
    assert len(fields) > 150  # the whole tree, nested sections included
    missing = [path for path, doc in fields.items() if doc.nested is None and not (doc.meaning or doc.unit)]
    assert missing == []
    assert fields["duration"].unit == "s"
    assert fields["null_space.K_n"].unit == "1/s"
    assert fields["realism.belt.enabled"].default == "False"


@dataclass
class Example:
    """An example tree."""

    # Time it takes,
    # on two lines [s].
    duration: float = 1.5
    gain: float = 2.0  # [1/s] a trailing comment with a leading unit
    # Camera position and target [m].
    position: list[float] = field(default_factory=list)
    target: list[float] = field(default_factory=list)
    inner: list[int] = field(default_factory=lambda: [1, 2])
    plain: str = "x"  # no unit here


def test_the_field_parser_on_a_known_class():
    """Comments above a field (over two lines), at its end (unit first), shared by the next
    field of the same type, and none: each read as written. Catches a comment given to the
    wrong field (a section took the comment of the list before it) or a lost unit."""
    docs = {d.name: d for d in nsdrake_docs.field_docs(Example)}
    assert (docs["duration"].meaning, docs["duration"].unit, docs["duration"].default) == (
        "Time it takes, on two lines",
        "s",
        "1.5",
    )
    assert (docs["gain"].meaning, docs["gain"].unit) == ("a trailing comment with a leading unit", "1/s")
    assert (docs["target"].meaning, docs["target"].unit) == ("Camera position and target", "m")
    assert (docs["inner"].meaning, docs["inner"].unit, docs["inner"].default) == ("", "", "[1, 2]")
    assert (docs["plain"].meaning, docs["plain"].unit) == ("no unit here", "")
    assert [f.name for f in dataclasses.fields(Example)] == list(docs)


def decision_tree_rows(text: str) -> dict[int, tuple[str, ...]]:
    """docs/decision_tree.md's mode table: mode → its levels' criteria, level 2 first."""
    words = {
        "obstacle avoidance": "obstacle",
        "joint limits": "joint_limits",
        "joint-limit avoidance": "joint_limits",
        "joint torque": "joint_torque",
        "joint-torque minimisation": "joint_torque",
        "manipulability": "manipulability",
        "manipulability maximisation": "manipulability",
    }
    rows = {}
    for line in text.splitlines():
        match = re.match(r"^\| (\d) \| ([^|]+) \| ([^|]+) \|$", line)
        if match:
            names = [match.group(2).strip()] + [w.strip() for w in match.group(3).split(",")]
            rows[int(match.group(1))] = tuple(words[w] for w in names if w != "nothing")
    return rows


def test_the_decision_tree_page_is_the_selector():
    """docs/decision_tree.md's table (each mode's level 2 and lower levels) is
    nsdrake.control.priority's ORDERINGS, every mode listed. Catches a mode or an ordering
    changed in the code but not on the page the `mode` columns link to."""
    from nsdrake.control.priority import ORDERINGS, Mode

    rows = decision_tree_rows((ROOT / "docs" / "decision_tree.md").read_text())
    assert rows == {int(m): tuple(c.value for c in ORDERINGS[m]) for m in Mode}
    swapped = (
        (ROOT / "docs" / "decision_tree.md").read_text().replace("| 2 | joint-torque", "| 3 | joint-torque")
    )
    assert decision_tree_rows(swapped) != rows


def test_a_docstring_role_renders_as_its_target():
    """A port's or a field's meaning read from a docstring shows ``:mod:`x``` as the literal
    x, never the raw role (the API page printed ':mod:nsdrake.control.actuator_limits')."""
    parts = nsdrake_docs.inline("clipped (:mod:`nsdrake.control.actuator_limits`: τ), :func:`~a.b` and `c`")
    text = "".join(p.astext() for p in parts)
    assert ":mod:" not in text and ":func:" not in text
    literals = [p.astext() for p in parts if p.tagname == "literal"]
    assert literals == ["nsdrake.control.actuator_limits", "a.b", "c"]
