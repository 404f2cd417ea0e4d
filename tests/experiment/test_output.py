"""Output folders (nsdrake/experiment/output.py): a manifest is a file anyone can edit or
ship inside a zipped run folder, so reclaiming a folder must never remove, or write,
anything outside it (issue 24, item 1).

Each test plants a user's file outside ``--out`` (beside it, at an absolute path, behind a
symbolic link inside it) and a manifest that names it, then checks that the file survives,
that nothing inside the folder was removed either (the refusal comes first), and that the
command says so in one line with exit status 2.
"""

from __future__ import annotations

import os

import pytest
from conftest import without_notices

from nsdrake.cli import main
from nsdrake.experiment.output import (
    MANIFEST,
    OutputFolderError,
    prepare_output_folder,
    remove_listed,
    take_over,
    unsafe_entry,
)

HEADER = "# nsdrake wrote the files listed below\n"


def planted(tmp_path, entry_for):
    """A released run folder ``run/`` holding traces.csv, a user's file outside it, a
    symbolic link ``run/link`` to the folder that holds the user's file, and a manifest
    listing traces.csv and ``entry_for(victim)``."""
    outside = tmp_path / "outside"
    outside.mkdir()
    victim = outside / "victim.txt"
    victim.write_text("the user's")
    run = tmp_path / "run"
    run.mkdir()
    (run / "traces.csv").write_text("t\n0\n")
    os.symlink(outside, run / "link")
    listed = ["traces.csv", "link", entry_for(victim)]
    (run / MANIFEST).write_text(HEADER + "".join(f"{e}\n" for e in listed))
    return run, victim


HOSTILE = {
    "parent": lambda victim: "../outside/victim.txt",
    "absolute": lambda victim: str(victim),
    "through a link": lambda victim: "link/victim.txt",
    "a dot-dot folder": lambda victim: "../outside/",
    "dot-dot inside": lambda victim: "sub/../../outside/victim.txt",
}


@pytest.mark.parametrize("kind", sorted(HOSTILE))
def test_reclaiming_never_removes_what_a_manifest_names_outside_the_folder(tmp_path, kind):
    """Catches the regression of issue 24: remove_listed joined each listed entry to the
    folder and unlinked it, so ../x, /abs/x and link/x deleted a user's file."""
    run, victim = planted(tmp_path, HOSTILE[kind])
    with pytest.raises(OutputFolderError, match=r"--overwrite refused: its \.nsdrake-run lists") as e:
        prepare_output_folder(run, overwrite=True)
    assert "\n" not in str(e.value) and "nothing was removed" in str(e.value)
    assert victim.read_text() == "the user's"
    assert (run / "traces.csv").is_file() and (run / "link").is_symlink()  # refused before removing


@pytest.mark.parametrize("kind", sorted(HOSTILE))
def test_remove_listed_refuses_on_its_own(tmp_path, kind):
    """The sweep calls remove_listed with its own selection of the manifest: the guard is in
    remove_listed, not only in the run's reclaim (a guard only in prepare_output_folder fails)."""
    run, victim = planted(tmp_path, HOSTILE[kind])
    with pytest.raises(OutputFolderError):
        remove_listed(run, ["traces.csv", HOSTILE[kind](victim)])
    assert victim.read_text() == "the user's" and (run / "traces.csv").is_file()


def test_a_listed_link_is_removed_itself_never_what_it_points_to(tmp_path):
    """A leaf that is a symbolic link is unlinked (it is inside the folder); following it
    would delete the user's file (Path.unlink on the resolved target, or rmtree, fails this)."""
    run, victim = planted(tmp_path, lambda victim: "traces.csv")
    os.symlink(victim, run / "to_victim")
    remove_listed(run, ["traces.csv", "link", "to_victim"])
    assert victim.read_text() == "the user's"
    assert sorted(os.listdir(run)) == [MANIFEST]


def test_a_folder_listed_through_a_link_swapped_in_later_is_not_followed(tmp_path):
    """The removal opens each folder with O_NOFOLLOW relative to its parent: a real folder
    checked safe and then replaced by a link (a race) is not followed (a removal by joined
    path names fails this)."""
    from nsdrake.experiment import output

    run, victim = planted(tmp_path, lambda victim: "traces.csv")
    (run / "sub").mkdir()
    checked = output.refuse_unsafe

    def swap_after_check(folder, listed):
        checked(folder, listed)
        (run / "sub").rmdir()
        os.symlink(victim.parent, run / "sub")

    output.refuse_unsafe, saved = swap_after_check, output.refuse_unsafe
    try:
        with pytest.raises(OutputFolderError, match="cannot remove sub/victim.txt"):
            remove_listed(run, ["sub/victim.txt"])
    finally:
        output.refuse_unsafe = saved
    assert victim.read_text() == "the user's"


@pytest.mark.parametrize(
    ("entry", "why"),
    [
        ("traces.csv", None),
        ("runs/0001/traces.csv", None),
        ("runs/0001/", None),
        ("", "an empty or binary path"),
        ("/etc/passwd", "an absolute path"),
        ("../x", "a path outside the folder"),
        ("a/../../x", "a path outside the folder"),
        ("./x", "a path that is not plain"),
        ("a//x", "a path that is not plain"),
        ("link/x", "a path through the symbolic link link"),
        ("missing/x", None),  # nothing there: nothing to remove, nothing to refuse
    ],
)
def test_unsafe_entry_names_each_kind(tmp_path, entry, why):
    """The boundary of the rule: plain relative paths pass (including a folder and a path
    that does not exist), each way out of the folder is named."""
    os.symlink(tmp_path, tmp_path / "link")
    assert unsafe_entry(tmp_path, entry) == why


def test_take_over_refuses_a_link_in_the_folder(tmp_path):
    """A sweep resumed into a folder writes into it: a symbolic link there (runs -> elsewhere)
    would carry its writes outside --out (take_over without the link check fails)."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    out = tmp_path / "sweep"
    out.mkdir()
    os.symlink(elsewhere, out / "runs")
    (out / MANIFEST).write_text(HEADER + "runs\nsweep.json\n")
    with pytest.raises(OutputFolderError, match="holds the symbolic link runs, which nsdrake never writes"):
        take_over(out)
    assert (out / "runs").is_symlink()


@pytest.mark.parametrize("kind", ["parent", "absolute", "through a link"])
def test_run_overwrite_with_a_hostile_manifest_is_one_line_and_runs_nothing(tmp_path, capsys, kind):
    """Through the command line, as the issue found it: `nsdrake run --overwrite` deleted the
    file and then ran as if nothing happened. Now: exit 2, one line, the user's file and the
    folder as they were, no simulation."""
    run, victim = planted(tmp_path, HOSTILE[kind])
    before = sorted(os.listdir(run))
    assert main(["run", "fig3", "--duration", "0.1", "--out", str(run), "--overwrite"]) == 2
    err = without_notices(capsys.readouterr().err)
    assert err.count("\n") == 1 and "lists" in err and str(run) in err
    assert victim.read_text() == "the user's"
    assert sorted(os.listdir(run)) == before


def test_sweep_overwrite_with_a_hostile_manifest_removes_nothing(tmp_path, capsys):
    """`nsdrake sweep --overwrite` over another sweep's folder removes the listed runs/ of
    the old sweep: a manifest listing runs/../../outside/victim.txt must not reach it."""
    run, victim = planted(tmp_path, lambda victim: "runs/../../outside/victim.txt")
    (run / "link").unlink()
    (run / MANIFEST).write_text(HEADER + "traces.csv\nsweep.json\nruns/../../outside/victim.txt\n")
    (run / "sweep.json").write_text('{"spec": "other.yaml", "identity": "other", "runs": 1}\n')
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "base: fig3\nduration: 0.1\naxes:\n  null_space.K_n: [50.0, 100.0]\nmetrics: [first_contact_time]\n"
    )
    assert main(["sweep", str(spec), "--out", str(run), "--overwrite", "--jobs", "1"]) == 2
    err = without_notices(capsys.readouterr().err)
    assert err.count("\n") == 1 and "nothing was removed" in err
    assert victim.read_text() == "the user's"
    assert sorted(os.listdir(run)) == sorted([MANIFEST, "traces.csv", "sweep.json"])
