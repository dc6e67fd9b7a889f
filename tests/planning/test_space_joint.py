"""The joint formulation in space (issue 36 item 3): `plan --hand fingerpro4 --formulation joint` solves the
search's segments as one IPOPT program (cito.space_joint.build_space_joint), the nodes free but the start and the
goal; the plan passes the physics check redone from its files, and plan.json records the formulation."""

import json

import numpy as np
import pytest

from trajectotree.cito.space_hand import hand_model
from trajectotree.cito.space_joint import build_space_joint, joint_knots
from trajectotree.cito.spatial import SPACE_INTERVALS, segment_spec
from trajectotree.cli import main
from trajectotree.config import Config, mu_plan
from trajectotree.planning.spatial import PLAN_JSON, PLAN_NPZ, recheck_space_plan
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import find_space_contact_plan

SMALL_GOAL = ["--goal-rpy", "0.6", "0", "0"]  # rad about x: 2 segments
SMALL_QUATERNION = (float(np.cos(0.3)), float(np.sin(0.3)), 0.0, 0.0)


def _read(out):
    with np.load(out / PLAN_NPZ) as npz:
        arrays = {name: npz[name] for name in npz.files}
    return out, json.loads((out / PLAN_JSON).read_text()), arrays


@pytest.mark.slow
def test_joint_formulation_plans_a_small_goal_that_passes_the_check_its_nodes_free(space_plan, tmp_path):
    """The joint formulation's plan of SMALL_GOAL beside the keyframes formulation's (the default: conftest's
    space_plan, `plan` of the same goal, planned once for the run)."""
    argv = ["plan", "--hand", "fingerpro4", *SMALL_GOAL, "--formulation", "joint", "--segment-workers", "1"]
    assert main([*argv, "--out", str(tmp_path / "joint")]) == 0
    joint, data, arrays = _read(tmp_path / "joint")
    assert data["formulation"] == "joint" and data["success"], data["status"]
    assert len(data["segments"]) == 1  # one program
    assert data["physics_check"]["passed"] and recheck_space_plan(joint).passed
    nodes = len(data["contact_plan"]["contact_sequence"])
    assert nodes >= 3 and len(arrays["t"]) == SPACE_INTERVALS * (nodes - 1) + 1
    _, keyframes, kf_arrays = _read(space_plan)
    assert keyframes["formulation"] == "keyframes" and len(keyframes["segments"]) == nodes - 1
    inner = SPACE_INTERVALS * np.arange(1, nodes - 1)  # the knots of the nodes between start and goal
    # keyframes pins each node at rest; the joint program moves the cube through them (rad/s, m/s)
    assert np.all(kf_arrays["v"][inner] == 0.0)
    assert np.linalg.norm(arrays["v"][inner], axis=-1).min() > 1e-3
    # both start and end at the same states: the start grasp and the goal at rest
    for name in ("x", "q"):
        np.testing.assert_allclose(arrays[name][[0, -1]], kf_arrays[name][[0, -1]], atol=1e-9)


def test_joint_program_shares_each_node_between_its_segments():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    mu = mu_plan(config.scene, config.search)
    plan = find_space_contact_plan(scene, SMALL_QUATERNION, config.search, mu)
    hand = hand_model(scene)
    specs = [segment_spec(hand, hand.chains, a, b) for a, b in zip(plan.nodes[:-1], plan.nodes[1:])]
    program = build_space_joint(hand, hand.chains, specs, mu)
    knots = joint_knots(program.rows)
    assert len(knots) == len(specs) >= 2
    assert program.z.shape[0] == knots[-1].stop == SPACE_INTERVALS * len(specs) + 1
    for before, after in zip(knots[:-1], knots[1:]):
        assert after.start == before.stop - 1  # one knot: the node
    # the node's nominal orientation is the same in both segments' rows, so one phi there serves both
    for a, b in zip(program.rows[:-1], program.rows[1:]):
        np.testing.assert_allclose(a.N[-1], b.N[0], atol=1e-12)
        np.testing.assert_array_equal(a.p_BC[-1], b.p_BC[0])


def test_an_unknown_formulation_in_space_exits_2_naming_it(tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["plan", "--hand", "fingerpro4", *SMALL_GOAL, "--formulation", "bogus", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "--formulation" in err and "'bogus'" in err and "keyframes, joint" in err
    assert not out.exists()
