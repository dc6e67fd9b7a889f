"""The cube's 180 deg turns about its edge diagonals (issue 36's axis-aligned goals) on fingerpro4: the turn about
the horizontal diagonal (1, 1, 0) planned by `trajectotree plan --hand fingerpro4`, rechecked from its files, at
its goal; its contact sequence moves a finger onto a face turned away from the finger's base, which the search
once left out as a dead end (the six edge-diagonal turns had no contact plan then)."""

import json
import math

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config
from trajectotree.geometry import BOX_FACE_NAMES, BOX_FACE_NORMALS, quaternion_angle, quaternion_matrices
from trajectotree.planning.spatial import recheck_space_plan
from trajectotree.scene.spatial import build_space_scene

HALF_TURN_ABOUT_XY = np.array([0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0])  # 180 deg about (1, 1, 0) / sqrt(2)


def _facing(scene, node: dict, finger: int) -> float:
    """The cosine between the finger's contact face's normal and the direction from the contact to the finger's
    base (joint 1), in W at the node's pose."""
    R = quaternion_matrices(np.array(node["object_pose"][:4]))
    contact = node["contacts"][finger]
    n_W = R @ BOX_FACE_NORMALS[BOX_FACE_NAMES.index(contact["face"])]
    to_base = scene.fingers[finger].p_W_joint[0] - (R @ np.array(contact["p_BC"]) + node["object_pose"][4:])
    return float(n_W @ to_base / np.linalg.norm(to_base))


@pytest.mark.slow
def test_a_half_turn_about_an_edge_diagonal_plans_and_passes(tmp_path, capsys):
    out = tmp_path / "edge"
    argv = ["plan", "--hand", "fingerpro4", "--goal-quat", *map(str, HALF_TURN_ABOUT_XY), "--segment-workers", "1"]
    # the search without the stance margin's preference, whose plan this reproduces (with it: 35 s instead of 20)
    argv += ["--config-text", "{search: {space_stance_margin: none}}"]
    assert main([*argv, "--out", str(out)]) == 0
    data = json.loads((out / "plan.json").read_text())
    assert data["success"], data["status"]
    assert data["physics_check"]["passed"] and data["integration"].startswith("trapezoidal")
    assert set(data["object"]) >= {"size", "mass", "inertia", "mu_plan"}
    check = recheck_space_plan(out)  # from the files alone
    assert check.passed, check.reason
    assert check.newton_euler_force_N <= 1e-4 and check.newton_euler_moment_Nm <= 1e-4
    with np.load(out / "plan.npz") as npz:
        x = npz["x"]
        assert x.shape[1] == 7 and npz["v"].shape[1] == 6 and npz["f_W"].shape[1:] == (4, 3)
    assert math.degrees(quaternion_angle(x[-1, :4], HALF_TURN_ABOUT_XY)) <= 2.0
    nodes = data["contact_plan"]["contact_sequence"]
    assert len(nodes) == 10  # 180 deg in segments of at most 20 deg: the geodesic, no detour
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    moves = [_facing(scene, n, n["switching_finger"]) for n in nodes if n["switching_finger"] is not None]
    assert min(moves) <= 0.0, moves  # a finger moved onto a face turned away from its base
    assert "physics check passed" in capsys.readouterr().out
