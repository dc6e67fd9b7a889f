"""The cube's 180 deg turns about its edge diagonals (issue 36's axis-aligned goals) on fingerpro4: the turn about
the horizontal diagonal (1, 1, 0) has a contact plan (`trajectotree search --hand fingerpro4`) to its goal, whose
sequence moves a finger onto a face turned away from the finger's base, which the search once left out as a dead
end (the six edge-diagonal turns had no contact plan then)."""

import json
import math

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config
from trajectotree.geometry import BOX_FACE_NAMES, BOX_FACE_NORMALS, quaternion_angle, quaternion_matrices
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


@pytest.mark.slow  # the search, ~10 s of CPU
def test_a_half_turn_about_an_edge_diagonal_has_a_contact_plan(capsys):
    """Search only: the trajectory optimization of such plans, its files and their recheck are the sweeps' and
    tests/cito/test_space_segment.py's (planning it here took 15 s more of the suite)."""
    argv = ["search", "--hand", "fingerpro4", "--goal-quat", *map(str, HALF_TURN_ABOUT_XY), "--json"]
    # the search without the stance margin's preference, whose plan this reproduces (with it the search is slower)
    argv += ["--config-text", "{search: {space_stance_margin: none}}"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["success"], data["reason"]
    nodes = data["contact_sequence"]
    assert len(nodes) == 10  # 180 deg in segments of at most 20 deg: the geodesic, no detour
    assert math.degrees(quaternion_angle(np.array(nodes[-1]["object_pose"][:4]), HALF_TURN_ABOUT_XY)) <= 1e-6
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    moves = [_facing(scene, n, n["switching_finger"]) for n in nodes if n["switching_finger"] is not None]
    assert min(moves) <= 0.0, moves  # a finger moved onto a face turned away from its base
