"""Every program the documentation shows runs. A complete program (a ```python block, or a
file shown with ``literalinclude``) is run as written, in its own process; a fragment (a
block that uses names the page defines in prose: ``plant``, ``q``, …) is listed in
FRAGMENTS with the test that runs it with those names bound. A new block in the docs is
either a program this test runs or a fragment someone lists, so none goes untested."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from pydrake.all import MultibodyPlant, Parser

import nsdrake
from nsdrake.studies import vendor_arms

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

# A fragment's distinctive text → the test that runs it.
FRAGMENTS = {
    "MakeStateSelectorMatrix": "tests/control/test_component_contract.py::"
    "test_the_docs_wiring_for_a_plant_with_more_joints_selects_the_arms",
    "step = nsdrake.ControllerStep(": "tests/docs/test_docs_programs.py::"
    "test_the_controller_step_fragment_gives_gravity_torques_at_rest",
}


def python_blocks() -> list[tuple[str, str]]:
    """(page, code) of every ```python block in the docs' pages (dedented: a block in a
    list item is indented)."""
    blocks = []
    for page in sorted(DOCS.glob("**/*.md")):
        if "_build" in page.parts:
            continue
        for code in re.findall(r"^[ ]*```python\n(.*?)^[ ]*```", page.read_text(), flags=re.S | re.M):
            blocks.append((str(page.relative_to(ROOT)), textwrap.dedent(code)))
    return blocks


def included_programs() -> list[Path]:
    """Every file a page shows with ``literalinclude`` as Python."""
    files = []
    for page in sorted(DOCS.glob("**/*.md")):
        for target, options in re.findall(r"```\{literalinclude\} (\S+)\n((?::\S+:.*\n)*)", page.read_text()):
            if ":language: python" in options:
                files.append((page.parent / target).resolve())
    return files


def fragment_of(code: str) -> str | None:
    matches = [key for key in FRAGMENTS if key in code]
    assert len(matches) <= 1, matches
    return matches[0] if matches else None


def test_every_fragment_is_listed_once_and_still_in_the_docs():
    """Each listed fragment matches exactly one block (a fragment dropped from the docs, or
    duplicated, is noticed), and the docs show at least one included program."""
    found = [fragment_of(code) for _, code in python_blocks()]
    for key in FRAGMENTS:
        assert found.count(key) == 1, key
    assert ROOT / "diagrams" / "own_arm.py" in included_programs()


def complete_programs() -> list[tuple[str, str]]:
    programs = [(page, code) for page, code in python_blocks() if fragment_of(code) is None]
    programs += [(str(path.relative_to(ROOT)), path.read_text()) for path in included_programs()]
    return programs


@pytest.mark.slow
@pytest.mark.parametrize("where, code", complete_programs(), ids=lambda v: str(v)[:40])
def test_every_complete_program_in_the_docs_runs(where, code, tmp_path):
    """Run as a reader would (python FILE from the repository's root, which the programs'
    relative paths assume), each must exit 0 within 600 s. Catches an example that no
    longer runs against the package (a renamed port, argument or import). A program that
    loads example-robot-data's arms skips, saying how to install it, where it is not
    installed (the README's test command leaves that 400 MB extra out; .ci/run has it)."""
    if 'installed_package("example-robot-data")' in code and vendor_arms.robots_folder() is None:
        pytest.skip(f"{where} loads {vendor_arms.PACKAGE}'s arms: {vendor_arms.INSTALL}")
    script = tmp_path / "program.py"
    script.write_text(code)
    result = subprocess.run(
        [sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, f"{where}: {result.stderr[-2000:]}"


def test_the_controller_step_fragment_gives_gravity_torques_at_rest(monkeypatch):
    """The architecture page's ControllerStep fragment, run as written from the repository's
    root with its free names bound: the Panda at rest at panda_wipe's start pose, x_d where
    the tool is, no force. On the first tick q̇_dⁿ = 0 and nothing moves, so Eq. 7 leaves
    τ = g(q): compared with the gravity torques of a plain Drake plant of the same URDF to
    1e-8 N m. Catches a fragment whose call no longer matches ControllerStep.step, or whose
    arguments are in the wrong order (x_d read as a velocity or an acceleration asks for a
    task torque on top of g)."""
    (code,) = [code for _, code in python_blocks() if fragment_of(code) == "step = nsdrake.ControllerStep("]
    q = np.array([0.0, 0.182, 0.0, -2.4, 0.0, 2.582, 0.785])
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(ROOT / "urdf" / "panda.urdf"))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    x_tool = plant.GetFrameByName("tool").CalcPoseInWorld(context).translation()
    g = -plant.CalcGravityGeneralizedForces(context)
    names = {"nsdrake": nsdrake, "Path": Path, "t": 0.0, "q": q, "v": np.zeros(7), "wrench": np.zeros(6)}
    names |= {"x_d": x_tool, "xdot_d": np.zeros(3), "xddot_d": np.zeros(3), "f_d": 0.0}
    monkeypatch.chdir(ROOT)
    exec(code, names)
    assert np.max(np.abs(g)) > 1.0  # the arm is loaded
    np.testing.assert_allclose(names["result"].tau, g, rtol=0, atol=1e-8)
