"""The keyframes figure of a contact plan in space (figures.space, `search --hand fingerpro4 --figure`): one 3D
panel per node, the box's corners and the fingers' links where the plan puts them; a bad --figure path exits 2
before the search."""

import math

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from trajectotree.cli import main  # noqa: E402
from trajectotree.config import Config  # noqa: E402
from trajectotree.figures.space import box_corners_W, figure_space_keyframes, finger_polylines  # noqa: E402
from trajectotree.geometry import box_signed_distances, quaternion_matrices  # noqa: E402
from trajectotree.scene.spatial import build_space_scene  # noqa: E402

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])


@pytest.fixture(scope="module")
def scene_plan(quarter_turn):
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    plan = quarter_turn(config.search)  # conftest's: searched once per process
    assert plan.success
    return scene, plan


def test_the_figure_draws_each_node_where_the_plan_puts_it(scene_plan):
    import matplotlib.pyplot as plt

    scene, plan = scene_plan
    fig = figure_space_keyframes(scene, plan)
    try:
        axes = [ax for ax in fig.axes if ax.name == "3d"]
        assert len(axes) == len(plan.nodes)
        for ax, node in zip(axes, plan.nodes):
            drawn = np.concatenate([np.array(line.get_data_3d()).T for line in ax.get_lines()])
            for point in (*box_corners_W(scene.object.half, node.object_pose), *finger_polylines(scene, node.q)[:, -1]):
                assert np.min(np.linalg.norm(drawn - point, axis=1)) < 1e-12  # each corner and fingertip drawn
    finally:
        plt.close(fig)


def test_fingertips_of_the_polylines_are_on_their_contacts(scene_plan):
    """The polylines end at the fingertip centres, r off each contact along the face's normal."""
    scene, plan = scene_plan
    node = plan.nodes[-1]
    tips = finger_polylines(scene, node.q)[:, -1]
    R = quaternion_matrices(node.object_pose[:4])
    gaps = box_signed_distances(scene.object.half, (tips - node.object_pose[4:]) @ R)
    assert np.allclose(gaps, scene.tip_radius, atol=2e-4)


@pytest.mark.slow
def test_search_writes_the_figure(tmp_path, capsys):
    path = tmp_path / "keyframes.png"
    argv = ["search", "--hand", "fingerpro4", "--goal-quat", *map(str, QUARTER_ABOUT_X), "--figure", str(path)]
    assert main(argv) == 0
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"figure: {path}" in capsys.readouterr().out


def test_a_bad_figure_path_exits_2_before_the_search(tmp_path, capsys):
    path = tmp_path / "keyframes.txt"
    argv = ["search", "--hand", "fingerpro4", "--goal-quat", *map(str, QUARTER_ABOUT_X), "--figure", str(path)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--figure" in err and "must end in .png or .pdf or .svg" in err
    assert list(tmp_path.iterdir()) == []
