"""Settings that were accepted and then did nothing, or blew up at the first step (issue 24,
item 5), refused where the user meets them: `nsdrake run` and `nsdrake compare` with a
--config file, one line on stderr, exit 2, before any simulation (no output folder).

The independent check of each refusal is the same command with the setting repaired (or
the same variant without the user's file) going past the check: a rule that refused
everything, or named the wrong file, fails.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from nsdrake import ControllerConfig, ControllerConfigError, NullSpaceImpedanceController
from nsdrake.cli import main
from nsdrake.experiment.scenario import ScenarioError, load_scenario
from nsdrake.station.models import models_dir
from nsdrake.studies.compare import check_variants, load_family, variant_scenario

FIG3_Q_D = "{joint1: 0.401, joint2: 0.972, joint3: 1.012, joint4: 0.614}"


def refused(tmp_path, capsys, config_text: str, *extra: str) -> str:
    """`nsdrake run fig3 --config <file>`: exit 2, one line naming the file, no folder."""
    config = tmp_path / "mine.yaml"
    config.write_text(config_text)
    out = tmp_path / "out"
    assert main(["run", "fig3", "--config", str(config), "--out", str(out), "--no-replay", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not out.exists()
    assert str(config) in err, err
    return err


@pytest.mark.parametrize(
    "text, expected",
    [
        (
            "desired_null_space: {source: posture, posture: {q_d: {joint1: 1.0e300, joint2: 0.972, "
            "joint3: 1.012, joint4: 0.614}, gain: -0.1}}",
            r"desired_null_space\.posture\.q_d\.joint1: must be within ±6\.283 \[rad\] "
            r"\(one turn either way\), got 1e\+300",
        ),
        (
            f"desired_null_space: {{source: posture, posture: {{q_d: {FIG3_Q_D}, "
            "weight: {joint2: 1.0e300}, gain: -0.1}}",
            r"desired_null_space\.posture\.weight\.joint2: must be in \(0, 1e\+06\], got 1e\+300",
        ),
        (
            f"desired_null_space: {{source: posture, posture: {{q_d: {FIG3_Q_D}, offset: {{joint3: -40.0}}, "
            "gain: -0.1}}",
            r"desired_null_space\.posture\.offset\.joint3: must be within ±6\.283",
        ),
        (
            f"desired_null_space: {{posture: {{q_d: {FIG3_Q_D}}}}}",
            r"desired_null_space\.posture\.q_d: must be empty: nothing uses it "
            r"\(desired_null_space\.source is criteria and null_space\.law is paper\)",
        ),
        (
            "desired_null_space: {posture: {gain: -0.1}}",
            r"desired_null_space\.posture\.gain: must be 0: nothing uses it",
        ),
        (
            f"null_space: {{law: kinematic_posture_pd, posture_stiffness: 10.0, posture_damping: 0.5}}\n"
            f"desired_null_space: {{posture: {{q_d: {FIG3_Q_D}, gain: -0.1}}}}",
            r"desired_null_space\.posture\.gain: must be 0: nothing uses it \(desired_null_space\.source is "
            r"criteria and null_space\.law is kinematic_posture_pd\)",
        ),
        (
            "desired_null_space: {posture: {weight: {joint1: 2.0}}}",
            r"desired_null_space\.posture\.weight: must be empty: nothing uses it",
        ),
        (
            "desired_null_space: {posture: {offset_time: 1.0}}",
            r"desired_null_space\.posture\.offset_time: must be 0: nothing uses it",
        ),
    ],
)
def test_a_posture_setting_that_overflows_or_that_nothing_uses_is_refused(tmp_path, capsys, text, expected):
    """q_d or an offset of 1e300 rad, a weight of 1e300 (each overflowed at the first step,
    numpy's warning leaking), and a posture q_d, gain, weight or offset time that no part of
    the configured controller reads (they were ignored, while an unused posture_stiffness
    was refused): each refused with the valid range or the reason, naming the field."""
    import re

    err = refused(tmp_path, capsys, text)
    assert re.search(expected, err), err


def test_the_posture_settings_a_controller_uses_are_taken():
    """The same fields where they are used: the posture source with q_d, weight, offset and
    gain, and a posture law with q_d and an offset (no gain): the controller is built."""
    urdf = models_dir() / "arm4.urdf"
    q_d = {"joint1": 0.4, "joint2": 0.97, "joint3": 1.0, "joint4": 0.6}
    source = ControllerConfig()
    source.desired_null_space.source = "posture"
    source.desired_null_space.posture = dataclasses.replace(
        source.desired_null_space.posture, q_d=q_d, weight={"joint2": 1e6}, offset={"joint1": 6.0}, gain=-0.1
    )
    law = ControllerConfig()
    law.null_space.law, law.null_space.posture_stiffness = "kinematic_posture_pd", 10.0
    law.null_space.posture_damping = 0.5  # a kinematic PD's damping is given (issue 25), not 2√K_ns
    law.desired_null_space.posture = dataclasses.replace(
        law.desired_null_space.posture, q_d=q_d, offset={"joint4": -0.5}, offset_time=1.0
    )
    for config in (source, law):
        NullSpaceImpedanceController(controller_model=urdf, config=config, normal=[0.0, 1.0])
    law.desired_null_space.posture = dataclasses.replace(law.desired_null_space.posture, gain=-0.1)
    with pytest.raises(ControllerConfigError, match=r"config\.desired_null_space\.posture\.gain: must be 0"):
        NullSpaceImpedanceController(controller_model=urdf, config=law, normal=[0.0, 1.0])


@pytest.mark.parametrize(
    "text, extra, expected",
    [
        (
            "push: {body: link3, force: [0.0, 5.0, 0.0], start_time: 0.5, duration: 0.05}",
            ("--duration", "0.2"),
            r"push\.start_time: 0\.5 s is at or after the run's end \(duration 0\.2 s\): "
            r"the push would never act",
        ),
        (
            "duration: 1.0\npush: {body: link3, force: [0.0, 5.0, 0.0], start_time: 1.0, duration: 0.05}",
            (),
            r"push\.start_time: 1 s is at or after the run's end \(duration 1 s\)",
        ),
        (
            "push: {body: world, force: [0.0, 5.0, 0.0], start_time: 0.1, duration: 0.05}",
            ("--duration", "0.2"),
            r"push\.body: 'world' cannot move \(it is the world or welded to it\): "
            r"a push on it would do nothing; "
            r"the bodies that move: link1, link2, link3, link4",
        ),
        (
            "push: {body: base, force: [0.0, 5.0, 0.0], start_time: 0.1, duration: 0.05}",
            ("--duration", "0.2"),
            r"push\.body: 'base' cannot move",
        ),
        (
            "push: {body: link9, force: [0.0, 5.0, 0.0], start_time: 0.1, duration: 0.05}",
            ("--duration", "0.2"),
            r"push\.body: no body named 'link9' in the station; "
            r"the bodies that move: link1, link2, link3, link4",
        ),
    ],
)
def test_a_push_that_would_never_act_is_refused(tmp_path, capsys, text, extra, expected):
    """A push starting at or after the run's end (by the scenario's duration or --duration)
    and a push on a body that cannot move (the world, the arm's welded base) did nothing:
    refused, listing the bodies that move."""
    import re

    err = refused(tmp_path, capsys, text, *extra)
    assert re.search(expected, err), err


def test_a_push_within_the_run_is_taken(tmp_path):
    """The same push on link3 inside the run passes every check (the scenario loads)."""
    config = tmp_path / "mine.yaml"
    config.write_text("push: {body: link3, force: [0.0, 5.0, 0.0], start_time: 0.1, duration: 0.05}")
    scenario = load_scenario("fig3", config=config, duration=0.2)
    assert scenario.push.enabled and scenario.push.start_time < scenario.duration


def test_compare_checks_every_variant_against_its_arm_and_names_the_users_file(tmp_path):
    """`compare null_space_laws --config` keyed by the Panda's joints: fig3's variants have
    other joints. Refused before any variant runs (no output folder), in one line naming
    the user's file (it named the family's file after 12 variants had run); the same
    variant without the file is fine. Through the console, exit 2, no traceback."""
    config = tmp_path / "panda_only.yaml"
    config.write_text("actuator_limits:\n  torque: {panda_joint1: 80.0}\n")
    out = tmp_path / "out"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "nsdrake",
            "compare",
            "null_space_laws",
            "--config",
            str(config),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.startswith("nsdrake: error")]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0] == (
        f"nsdrake: error: {config}: actuator_limits.torque.panda_joint1: unknown joint; the arm's joints are "
        "joint1, joint2, joint3, joint4 (in the variant 'fig3 / paper' of null_space_laws)"
    ), lines[0]
    assert not out.exists() and "running" not in result.stdout, result.stdout  # no folder claimed
    family = load_family("null_space_laws")
    fig3 = next(v for v in family.variants if v.scenario == "fig3")
    check_variants(dataclasses.replace(family, variants=(fig3,)), None, None)  # fine without the file


def test_compare_with_a_shorter_duration_keeps_the_familys_push_and_says_so():
    """`compare --duration` shorter than a family's own push: the variant is taken (its row
    says the run ends before the push), while a family or config whose push lies after its
    own run's end is refused."""
    family = load_family("null_space_laws")
    index = next(i for i, v in enumerate(family.variants) if v.name.startswith("push"))
    scenario = variant_scenario(family, index, None, 2.0)
    assert scenario.duration == 2.0 and scenario.push.start_time == 3.5
    late = dataclasses.replace(
        family.variants[index], overrides=family.variants[index].overrides | {"duration": 3.0}
    )
    with pytest.raises(ScenarioError, match=r"push\.start_time: 3\.5 s is at or after the run's end"):
        variant_scenario(dataclasses.replace(family, variants=(late,)), 0, None, 2.0)


def test_the_cli_runs_from_a_fresh_process_with_a_good_posture(tmp_path):
    """Sanity of the checks' wiring at the console: a posture source with every field used
    passes the checks and reaches the simulation (a 0.02 s run, exit 0 or 1)."""
    config = tmp_path / "posture.yaml"
    config.write_text(f"desired_null_space: {{source: posture, posture: {{q_d: {FIG3_Q_D}, gain: -0.1}}}}")
    out = tmp_path / "out"
    assert main(
        ["run", "fig3", "--config", str(config), "--duration", "0.02", "--out", str(out), "--no-replay"]
    ) in (
        0,
        1,
    )
    assert (out / "traces.csv").exists() or any(Path(out).iterdir())


PANDA_Q_D = (
    "{panda_joint1: 0.0, panda_joint2: 0.182, panda_joint3: 0.0, panda_joint4: %s, panda_joint5: 0.0, "
    "panda_joint6: 2.582, panda_joint7: 0.785}"
)


@pytest.mark.parametrize(
    "posture, expected",
    [
        (
            f"{{q_d: {PANDA_Q_D % '0.3'}, gain: -0.263}}",
            r"posture\.q_d\.panda_joint4: q_d = 0\.3 is outside the joint's limits \[-3\.0718, -0\.0698\]",
        ),
        (
            f"{{q_d: {PANDA_Q_D % '-2.4'}, offset: {{panda_joint4: 2.5}}, gain: -0.263}}",
            r"posture\.q_d\.panda_joint4: q_d \+ offset = 0\.1 is outside the joint's limits",
        ),
    ],
)
def test_a_posture_beyond_a_joints_limits_is_refused(tmp_path, capsys, posture, expected):
    """A posture q_d (or q_d plus its offset) outside the Panda's joint-4 limits would drive
    the joint into its stop: refused before any simulation, naming the joint and limits;
    the same posture at −2.4 rad (inside) is taken by the same command up to the run."""
    import re

    config = tmp_path / "mine.yaml"
    config.write_text(f"desired_null_space: {{source: posture, posture: {posture}}}")
    out = tmp_path / "out"
    assert main(["run", "panda_self_motion", "--config", str(config), "--out", str(out), "--no-replay"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(expected, err) and "mine.yaml" in err, err
    assert not out.exists()
    config.write_text(
        f"desired_null_space: {{source: posture, posture: {{q_d: {PANDA_Q_D % '-2.4'}, gain: -0.263}}}}"
    )
    args = [
        "run",
        "panda_self_motion",
        "--config",
        str(config),
        "--duration",
        "0.01",
        "--out",
        str(out),
        "--no-replay",
    ]
    assert main(args) in (0, 1)


def test_compare_names_the_variant_that_refuses_a_setting_only_some_variants_take(tmp_path):
    """`--config` with a posture gain: the variants whose source is the posture take it,
    the others (source criteria: nothing reads it) refuse it. Refused in one line naming
    the user's file and the first variant that refuses it (it named only the file), and
    checked on each variant with its overrides on (the family's base scenario was checked
    with the file before the variant's overrides, so even the variants that take it were
    refused, with the base's source in the message)."""
    config = tmp_path / "posture_gain.yaml"
    config.write_text("desired_null_space:\n  posture:\n    gain: -0.3\n")
    family = load_family("null_space_laws")
    paper, kinematic = (
        next(v for v in family.variants if v.name == name)
        for name in ("panda_wipe / paper", "panda_wipe / kinematic PD")
    )
    check_variants(
        dataclasses.replace(family, variants=(paper,)), config, None
    )  # the posture's source: taken
    with pytest.raises(ScenarioError) as caught:
        check_variants(dataclasses.replace(family, variants=(paper, kinematic)), config, None)
    assert str(caught.value) == (
        f"{config}: desired_null_space.posture.gain: must be 0: nothing uses it "
        "(desired_null_space.source is criteria and null_space.law is kinematic_posture_pd), got -0.3 "
        "(in the variant 'panda_wipe / kinematic PD' of null_space_laws)"
    ), str(caught.value)
