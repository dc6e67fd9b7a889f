"""Plans whose every stance met the stance margin still dropped at friction 0.4 (issue 37, branch drop37): the margin
was the world's friction 0.4, but the closed loop's grasp QP gives its cones controller.grasp.friction_safety x the
estimate, 0.32 there, and the swings' stances of seed-0 goal 13's plan needed 0.35-0.37 within the motors. The
margin is now that QP's friction (docs/measurements.md "Why plans at the margin drop")."""

import json

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, mu_plan
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.tree import _SpaceSearch

WORLD_MU = 0.4  # the closed loop's slippery world (planned at scene.mu 0.7)
# seed-0 SO(3) goal 13 ([qw, qx, qy, qz]): its plan at the margin 0.4 had 9/9 stances there and dropped at friction
# 0.4 (4.50 s) and at mass x1.5 (4.71 s), closed loop (/work/sweeps/share50)
GOAL_13 = (0.3158497023753437, -0.3766650622404895, -0.8705920563605003, -0.020781429180171163)
# the sweep's first pass (search.space_margin_first_share 0.5): goal 13's plan at the margin takes ~8 s of CPU, near
# the default share's 10 s
SWEEP = "{search: {space_margin_first_share: 0.5}}"


def test_the_margin_is_the_closed_loop_s_cones_in_the_slippery_world():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    search = _SpaceSearch(scene, np.array(GOAL_13), config.search, mu_plan(config.scene, config.search))
    closed_loop_cones = config.controller.grasp.friction_safety * WORLD_MU
    assert search.mu_hold == pytest.approx(closed_loop_cones, abs=1e-4)
    assert search.hold_frictions == pytest.approx((closed_loop_cones, 0.49), abs=1e-4)  # prefer: then mu_plan


@pytest.mark.slow  # a plan (~20 s) and two closed-loop runs of 8.5 s
def test_goal_13_planned_at_the_margin_holds_in_both_worlds_closed_loop(tmp_path):
    out = tmp_path / "g13"
    goal = [str(v) for v in GOAL_13]
    args = ["--hand", "fingerpro4", "--goal-quat", *goal, "--segment-workers", "1", "--config-text", SWEEP]
    assert main(["plan", *args, "--out", str(out)]) == 0
    contact_plan = json.loads((out / "plan.json").read_text())["contact_plan"]
    assert contact_plan["mu_margin"] == pytest.approx(0.32, abs=1e-3)
    assert contact_plan["margin_stances"] == contact_plan["stances"]
    for world in (["--sim-mu", str(WORLD_MU)], ["--sim-mass", "0.141"]):
        assert main(["simulate", str(out), "--closed-loop", *world]) == 0
        sim = json.loads((out / "sim.json").read_text())
        assert not sim["dropped"], (world, sim["drop_time_s"])
        assert sim["within_15deg"], (world, sim["final_orientation_error_deg"])
