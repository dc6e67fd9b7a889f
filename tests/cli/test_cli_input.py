"""What a user types, through the command line: values with a minus sign, config files that are
no YAML or empty, a mass the motors cannot carry, the goal's bound in enough digits, a plan
folder whose files disagree, pushes after the run, long failure reasons and the demo's words.
Each test checks the exit code, the message and the files left."""

import argparse
import json
import math
from pathlib import Path

import pytest

from trajectotree.cli import NUMBER_LIKE, build_parser, main
from trajectotree.cli.common import REASON_WIDTH, reason_lines
from trajectotree.cli.demo_cmd import print_summary
from trajectotree.cli.simulate_cmd import final_error_line


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ---- the object's mass against what the hand can carry ------------------------------------------


def test_a_mass_the_motors_cannot_carry_is_refused_with_the_limit(tmp_path, capsys):
    (tmp_path / "heavy.yaml").write_text("scene:\n  box_mass: 4.0\n")
    option = "--mass (scene.box_mass) = "
    cases = [
        (["search", "--goal", "1.57", "--mass", "10", "--figure", str(tmp_path / "k.png")], option + "10.0 kg"),
        (["plan", "--goal", "1.57", "--mass", "5", "--out", str(tmp_path / "p")], option + "5.0 kg"),
        (["demo", "--mass", "3.3", "--out", str(tmp_path / "d")], option + "3.3 kg"),
        (["sweep", "--goals", "1", "--mass", "3.3", "--out", str(tmp_path / "s")], option + "3.3 kg"),
        (
            ["plan", "--goal", "1", "--config", str(tmp_path / "heavy.yaml"), "--out", str(tmp_path / "p")],
            "scene.box_mass = 4.0 kg",
        ),
    ]
    for args, value in cases:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert f"trajectotree {args[0]}: error: {value} is more than the hand can hold" in err, err
        assert "the strongest of the 2139 candidate initial grasps holds at most 3.22 kg" in err
        assert "3.22 kg at rest with four fingers" in err and "1 N m torque limit" in err, err
        assert err.rstrip().endswith("valid range: [0.001, 3.22] kg"), err
    assert listing(tmp_path) == ["heavy.yaml"]  # nothing written


def test_the_printed_mass_limit_is_accepted_and_a_stance_limit_warned(capsys):
    """3.22 kg is within the hold limit (3.226 kg, printed rounded down) but over what three fingers
    carry while the fourth switches (1.01 kg): a warning, and the search finds a plan that
    switches no finger (a 0.05 rad roll)."""
    assert main(["search", "--goal", "0.05", "--segments", "1", "--mass", "3.22", "--json"]) == 0
    captured = capsys.readouterr()
    assert "warning: --mass (scene.box_mass) = 3.22 kg is more than three fingers can hold while the fourth " in (
        captured.err
    )
    assert "at most 1.01 kg" in captured.err and "search.max_stance_force 10 N" in captured.err
    plan = json.loads(captured.out)
    assert plan["success"] and all(n["switching_finger"] is None for n in plan["contact_sequence"])
    assert main(["search", "--goal", "0.05", "--segments", "1", "--json"]) == 0  # 50 g: no warning
    assert capsys.readouterr().err == ""


def test_scene_states_the_payload(capsys):
    assert main(["scene", "--mass", "5"]) == 0  # scene reports, as for an object it cannot grasp
    out = capsys.readouterr().out
    assert "payload: the initial grasps hold at most 3.22 kg at rest, 1.01 kg while a finger lets go" in out
    assert "the hand CANNOT hold the object's 5 kg (planning refuses it)" in out
    assert main(["scene", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)["reach"]["payload"]
    assert payload["grasps"] == 2139 and math.isclose(payload["switch_kg"], 10 / 9.81)


# ---- values that start with a minus sign ----------------------------------------------------------


def subcommand_parsers():
    """{name: parser} of every subcommand."""
    parser = build_parser()
    (subparsers,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return subparsers.choices


# --goal and --goal-pose exclude each other, so neither is required
REQUIRED = {"simulate": ["p"], "state": ["r", "--time", "1"], "report": ["s"]}


def test_every_option_that_takes_a_value_accepts_one_with_a_minus_sign():
    """argparse alone reads "-1e-1" as an unknown option ("expected one argument"); no option
    looks like a negative number, so every such token is a value."""
    checked = 0
    for name, parser in subcommand_parsers().items():
        for action in parser._actions:
            assert not any(NUMBER_LIKE.match(s) for s in action.option_strings), action.option_strings
            if not action.option_strings or action.nargs == 0 or action.dest == "help":
                continue
            value = "-7" if action.type is int else "-1e-1"
            count = action.nargs if isinstance(action.nargs, int) else 1
            args = parser.parse_args([*REQUIRED.get(name, []), action.option_strings[0], *[value] * count])
            parsed = getattr(args, action.dest)
            expected = (action.type or str)(value)
            assert parsed == (expected if action.nargs is None else [expected] * count), (name, action.dest)
            checked += 1
    assert checked > 40  # --goal, --mass, --box-size, --push, --polygon, --max-goal, --seed, ...
    args = build_parser().parse_args(["simulate", "p", "--push", "-0.2,0@3", "--polygon", "-0.07,-0.04"])
    assert args.push == "-0.2,0@3" and args.polygon == "-0.07,-0.04"


def test_negative_values_reach_the_range_checks(tmp_path, capsys):
    assert main(["search", "--goal", "-63"]) == 2
    assert capsys.readouterr().err == (
        "trajectotree search: error: --goal = -63.0 is out of range; valid range: [-20 pi, 20 pi] rad, "
        "20 pi = 62.83185307\n"
    )
    assert main(["scene", "--box-size", "-0.1", "0.1"]) == 2
    assert "--box-size W (scene.box_width) = -0.1 is out of range; valid range: (0, 0.3]" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "none"), "--push", "-0.2,0@3"]) == 2  # the folder, not the push
    assert "PLAN_DIR" in capsys.readouterr().err and listing(tmp_path) == []
    assert main(["search", "--goal", "-1e-1", "--segments", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["goal"] == -0.1


# ---- the goal's bound in enough digits --------------------------------------------------------------


def test_the_goal_bound_prints_pi_in_digits_that_are_within_it(capsys):
    assert main(["search", "--goal", "62.831854"]) == 2  # just above 20 pi: the bound printed is within it
    assert capsys.readouterr().err == (
        "trajectotree search: error: --goal = 62.831854 is out of range; valid range: [-20 pi, 20 pi] rad, "
        "20 pi = 62.83185307\n"
    )
    assert main(["search", "--goal", "-3.14159265", "--segments", "1", "--config", str(ONE_GRID), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["goal"] == -3.14159265
    assert main(["search", "--goal-pose", "0", "0", "-62.9"]) == 2  # a pose's orientation: its entry named
    assert "--goal-pose[2] = -62.9 is out of range; valid range: [-20 pi, 20 pi] rad" in capsys.readouterr().err


# ---- config files that are no YAML, or empty --------------------------------------------------------


def test_a_binary_or_empty_config_file_is_refused_naming_it(tmp_path, capsys):
    binary, empty, comments, defaults = (tmp_path / n for n in ("b.yaml", "e.yaml", "c.yaml", "d.yaml"))
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR")
    empty.write_text("")
    comments.write_text("# to do\n")
    defaults.write_text("{}\n")
    out = tmp_path / "p"
    for path, message in (
        (binary, "is not a text file (byte 0 is not UTF-8); give a YAML file"),
        (empty, "holds no settings (it is empty, or only comments or null); write the fields to change, {} for"),
        (comments, "holds no settings"),
    ):
        for command in (["plan", "--goal", "0.1", "--out", str(out)], ["scene"]):  # simulate: with a plan, below
            assert main([*command, "--config", str(path)]) == 2, (command, path)
            err = capsys.readouterr().err
            assert f"error: config file {str(path)!r} {message}" in err and "Traceback" not in err, err
    assert listing(tmp_path) == ["b.yaml", "c.yaml", "d.yaml", "e.yaml"]  # nothing written
    assert main(["scene", "--config", str(defaults), "--json"]) == 0  # {}: the defaults, deliberately
    assert json.loads(capsys.readouterr().out)["object"]["mass_kg"] == 0.05


# ---- long failure reasons ---------------------------------------------------------------------------------

# One contact grid (no refinement) and a goal one segment cannot reach: the search fails at once.
ONE_GRID = Path(__file__).with_name("one_grid.yaml")


def test_a_long_failure_reason_is_a_short_line_with_the_details_after(capsys):
    assert main(["search", "--goal", "3.0", "--segments", "1", "--config", str(ONE_GRID), "--json"]) == 0
    reason = json.loads(capsys.readouterr().out)["reason"]
    assert len(reason) > 250 and "; " in reason  # one line of the search's clauses
    assert main(["search", "--goal", "3.0", "--segments", "1", "--config", str(ONE_GRID)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "goal +3.0000 rad, N = 2: no plan: no plan from 0 searched initial grasp(s) of 2139"
    details = lines[1 : lines.index(next(line for line in lines if line.startswith("search ")))]
    assert all(len(line) <= 2 + REASON_WIDTH for line in details)
    assert details[0].startswith("  no plan from 0 searched initial grasp(s) of 2139 (2139 skipped by cheap")
    assert "  last searched none" in details and "  moves refused (mu_plan 0.49): none" in details
    # nothing is lost: the lines hold the reason's clauses, in order, wrapped between words
    assert " ".join(line.strip() for line in details) == " ".join(reason.replace("; ", " ").split())


def test_reason_lines_keep_a_short_reason_and_split_a_long_one_outside_brackets():
    assert reason_lines("Solve_Succeeded") == ("Solve_Succeeded", [])
    long = "first part (a; b) of it; " + "x" * 120 + "; last"
    summary, details = reason_lines(long)
    assert summary == "first part of it"
    assert details[0] == "first part (a; b) of it" and details[-1] == "last"
    assert all(len(line) <= REASON_WIDTH for line in details) and "".join(details[1:-1]).replace(" ", "") == "x" * 120


# ---- a saved plan, simulated (tiny_plan: tests/conftest.py's one-segment plan of 0.1 rad) ------------------


def copy_plan(plan: Path, to: Path, **config_changes) -> Path:
    """plan.npz of `plan` beside its plan.json with config sections changed, e.g. scene={...}."""
    to.mkdir()
    (to / "plan.npz").write_bytes((plan / "plan.npz").read_bytes())
    data = json.loads((plan / "plan.json").read_text())
    for section, changes in config_changes.items():
        data["config"][section].update(changes)
    (to / "plan.json").write_text(json.dumps(data))
    return to


@pytest.mark.slow
def test_simulate_refuses_a_plan_npz_beside_another_plans_plan_json(tiny_plan, tmp_path, capsys):
    cases = [
        (
            {"scene": {"box_height": 0.08}},
            "its contact points lie up to 10.00 mm off the 0.20 x 0.08 m box plan.json records (finger ",
        ),
        (
            {"scene": {"initial_pose": [0.01, 0.0, 0.0]}},
            "it starts at pose [0.0, 0.0, 0.0], plan.json's scene.initial_pose is [0.01, 0.0, 0.0]",
        ),
        ({"cito": {"knots_per_segment": 6}}, "it has 13 knots, plan.json's 2 nodes of cito.knots_per_segment 6 make 7"),
        ({"cito": {"dt": 0.05}}, "its knots are 0.1-0.1 s apart, plan.json's cito.dt is 0.05 s"),
    ]
    for k, (changes, message) in enumerate(cases):
        folder = copy_plan(tiny_plan, tmp_path / str(k), **changes)
        assert main(["simulate", str(folder), "--html", str(tmp_path / f"{k}.html")]) == 2, changes
        err = capsys.readouterr().err
        assert f"error: {str(folder / 'plan.npz')!r} does not belong to the plan {str(folder / 'plan.json')!r}" in err
        assert message in err, err
        assert sorted(p.name for p in folder.iterdir()) == ["plan.json", "plan.npz"]  # no sim.json, no sim.npz
    assert not list(tmp_path.glob("*.html"))
    taller = copy_plan(tiny_plan, tmp_path / "taller", scene={"box_height": 0.12})  # the other way round
    assert main(["simulate", str(taller)]) == 2
    assert "its contact points lie up to 10.00 mm off the 0.20 x 0.12 m box" in capsys.readouterr().err


@pytest.mark.slow
def test_simulate_refuses_a_push_after_the_run_and_takes_a_negative_one(tiny_plan, tmp_path, capsys):
    folder = copy_plan(tiny_plan, tmp_path / "plan")
    for push in ("1,1@1e9", "-0.2,0@3", "0,1@1.7"):
        assert main(["simulate", str(folder), "--push", push]) == 2
        assert capsys.readouterr().err == (
            f"trajectotree simulate: error: --push {push!r} starts at {float(push.split('@')[1]):g} s, when the run is "
            "over: it lasts 1.7 s (the plan's 1.2 s and sim.settle_time 0.5 s); valid range of T: [0, 1.7) s\n"
        )
        assert sorted(p.name for p in folder.iterdir()) == ["plan.json", "plan.npz"]
    (tmp_path / "b.yaml").write_bytes(b"\x89PNG\r\n\x1a\n\x00")
    assert main(["simulate", str(folder), "--config", str(tmp_path / "b.yaml")]) == 2
    assert "is not a text file (byte 0 is not UTF-8)" in capsys.readouterr().err
    assert main(["simulate", str(folder), "--push", "-0.2,0@0.5", "--json"]) == 0
    sim = json.loads(capsys.readouterr().out)
    assert sim["conditions"]["push"] == {"force": [-0.2, 0.0], "time_s": 0.5, "duration_s": 0.2}
    assert sim["dropped"] is False and sim["error_at_drop"] is None and len(sim["final_error"]) == 3


def test_the_final_error_line_names_the_end_and_the_drop():
    held = {"final_error": [0.001, 0.002, 0.003], "error_at_drop": None}
    assert final_error_line(held) == "final error x 1.0 mm, y 2.0 mm, theta 0.003 rad at the end of the run"
    caught = {"final_error": [0.0, 0.001, 0.002], "error_at_drop": [0.01, 0.06, 0.714]}
    assert final_error_line(caught) == (
        "final error x 0.0 mm, y 1.0 mm, theta 0.002 rad at the end of the run; "
        "at the drop: x 10.0 mm, y 60.0 mm, theta 0.714 rad"
    )


# ---- the demo's words --------------------------------------------------------------------------------------


def demo_summary(**plan) -> dict:
    base = {
        "method": "trajectotree",
        "goal": math.pi / 2,
        "success": True,
        "converged": True,
        "status": "Solve_Succeeded",
        "search_time_s": 0.48,
        "build_time_s": 0.46,
        "solve_time_s": 4.59,
        "total_time_s": 2.97,
        "iterations": 270,
        "cost": 361.4,
        "switching_fingers": [None, 0, 3],
        "segment_programs": 2,
    }
    simulation = {
        "sim_time_s": 3.1, "duration_s": 2.9, "dropped": True, "drop_time_s": 1.2, "mae_x": 0.001, "mae_y": 0.002,
        "mae_theta": 0.01, "final_error": [0.0, 0.0, 0.004], "error_at_drop": [0.0, 0.05, 0.714],
    }  # fmt: skip
    files = ["plan.json", "plan.npz", "keyframes.png", "sim.json", "sim.npz", "playback.html", "forces.png"]
    return {"object": "0.20 x 0.10 m box", "plan": base | plan, "simulation": simulation, "files": files}


def test_the_demo_labels_its_times_and_says_to_open_the_playback(capsys):
    print_summary(demo_summary(), Path("demo"), "box")
    out = capsys.readouterr().out
    assert "  CITO (IPOPT)      5.05 s summed   over its 2 segment programs, solved in parallel: build 0.46 s" in out
    assert "  total planning    2.97 s wall     search and CITO: converged, physics check passed" in out
    assert "  contact search    0.48 s wall " in out and "  simulation        3.10 s wall " in out
    assert "final theta error 0.004 rad (0.714 rad at the drop)" in out
    assert out.endswith("open demo/playback.html in a browser to watch the run (offline, any browser)\n")
    long = "1 of 9 pieces failed after retries; nodes 8-9 (links): physics check failed: " + "finger 3 sinks " * 9
    print_summary(demo_summary(status=long, success=False, segment_programs=0), Path("demo"), "box")
    lines = capsys.readouterr().out.splitlines()
    cito = next(line for line in lines if line.startswith("  CITO"))
    assert cito.endswith(
        "s wall     one program: build 0.46 s, solve 4.59 s, 270 iterations; 1 of 9 pieces failed after retries"
    )
    assert lines[lines.index(cito) + 1].startswith("      nodes 8-9 (links): physics check failed: finger 3 sinks")


def test_help_calls_the_object_a_box_or_any_convex_polygon(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "plan a rotation of the object, a box or any convex polygon" in text and "box rotation" not in text
    for command in ("plan", "search", "demo"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "goal orientation of the object, rad in W, any number within +-20 pi" in text, command
