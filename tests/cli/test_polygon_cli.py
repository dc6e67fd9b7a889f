"""Objects beyond the box from the command line: --polygon, its bad inputs (exit 2,
the problem named, nothing written), `scene` telling whether the hand can grasp the object,
and the HTML playback of a polygon carrying its mesh."""

import base64
import json
import math
import re

import numpy as np
import pytest

from trajectotree.cli import build_parser, main
from trajectotree.cli.common import config_from_args, in_option_terms, parse_polygon
from trajectotree.config import Config, ConfigError, ObjectConfig, SceneConfig, save_config
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import initial_grasp_candidates

TRIANGLE = "0.07,-0.040415 0,0.080829 -0.07,-0.040415"  # side 0.14 m, about its centroid
TINY = "0,0 0.04,0 0.02,0.04"  # too small: fingers 0 and 3 reach no contact
BAD_POLYGONS = [
    (
        "0.1,0 0,0.1",
        "--polygon (scene.object.vertices) = [[0.1, 0.0], [0.0, 0.1]]: a polygon needs at least 3 vertices, got 2",
    ),
    (
        "0,0 0.1,0 0.1,0.1 0,0.1 0.05,0.05",
        "the polygon is not convex (it turns the other way at vertex 4, (0.05, 0.05))",
    ),
    ("0,0 0.1,0.1 0.1,0 0,0.1", "the polygon is self-intersecting (its edges turn by 0 deg in all"),
    ("0,0 0.1,0 0.1,0 0,0.1", "vertices 1 and 2 repeat the point (0.1, 0)"),
    ("0,0 0.1,a 0,0.1", "--polygon vertex 1 '0.1,a' is not x,y (two numbers in m"),
    ("0,0 0.1 0,0.1", "--polygon vertex 1 '0.1' is not x,y"),
    ("0,0 0.1,0,0 0,0.1", "--polygon vertex 1 '0.1,0,0' is not x,y"),
    ("", "--polygon '' has no vertices"),
    ("0,0 1.5,0 0,0.1", "--polygon (scene.object.vertices[1][0]) = 1.5 is out of range; valid range: [-1, 1]"),
    (
        "0,0 0.5,0 0,0.1",
        "--polygon (scene.object.vertices): a vertex is 0.335 m from the centroid; valid range: at most 0.3 m",
    ),
    ("0,0 nan,0 0,0.1", "--polygon (scene.object.vertices[1][0]) = nan is not a finite number"),
    (
        "0,0 0.02,0 0,0.02",
        "--polygon (scene.object.vertices): edge 1 is 0.02 m long; contacts keep 0.015 m and 0.015 m from its "
        "corners (scene.corner_margin = 0.015 m at a right angle, less at a blunter corner), so it must be longer "
        "than 0.03 m",
    ),
]


def listing(folder) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("polygon, message", BAD_POLYGONS)
def test_bad_polygons_exit_2_naming_the_problem_and_write_nothing(polygon, message, tmp_path, capsys):
    for args in (
        ["scene", "--polygon", polygon, "--figure", str(tmp_path / "f.png")],
        ["plan", "--goal", "0.1", "--segments", "1", "--polygon", polygon, "--out", str(tmp_path / "p")],
        ["demo", "--polygon", polygon, "--out", str(tmp_path / "d")],
    ):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert err.startswith(f"trajectotree {args[0]}: error: ") and message in err, (args, err)
        assert listing(tmp_path) == []


def test_polygon_and_box_size_together_exit_2(tmp_path, capsys):
    assert main(["scene", "--polygon", TRIANGLE, "--box-size", "0.2", "0.1"]) == 2
    assert "--polygon and --box-size both describe the object: give one of them" in capsys.readouterr().err


def test_polygon_maps_to_object_vertices_and_box_size_back_to_the_box(tmp_path):
    parser = build_parser()
    config = config_from_args(parser.parse_args(["scene", "--polygon", TRIANGLE, "--mass", "0.08"]))
    assert config.scene.object.vertices == ((0.07, -0.040415), (0.0, 0.080829), (-0.07, -0.040415))
    assert config.scene.box_mass == 0.08 and not config.scene.shape.is_box
    path = tmp_path / "triangle.yaml"
    save_config(config, path)  # a config file with a polygon; --box-size on top makes the object a box
    boxed = config_from_args(parser.parse_args(["scene", "--config", str(path), "--box-size", "0.16", "0.08"]))
    assert boxed.scene.object == ObjectConfig() and (boxed.scene.box_width, boxed.scene.box_height) == (0.16, 0.08)
    assert boxed.scene.box_mass == 0.08


def test_parse_polygon_reads_signed_and_exponent_numbers():
    assert parse_polygon(" -7e-2,-0.04  0.07,-4e-2\t0,+0.08 ") == ((-0.07, -0.04), (0.07, -0.04), (0.0, 0.08))


def test_option_terms_keep_an_elements_index():
    args = build_parser().parse_args(["scene", "--polygon", TRIANGLE])
    element = ConfigError(field="scene.object.vertices", index=(2, 0), value=0.5, valid="[-1, 1]")
    named = in_option_terms(element, args)
    assert str(named) == "--polygon (scene.object.vertices[2][0]) = 0.5 is out of range; valid range: [-1, 1]"
    assert (named.field, named.index, named.value, named.valid) == ("scene.object.vertices", (2, 0), 0.5, "[-1, 1]")
    short = ConfigError(field="scene.object.vertices", problem="edge 1 is short")
    assert str(in_option_terms(short, args)) == "--polygon (scene.object.vertices): edge 1 is short"
    unset = ConfigError(field="scene.mu", value=0, valid="(0, 5]")
    assert str(in_option_terms(unset, args)) == "scene.mu = 0 is out of range; valid range: (0, 5]"  # not set


def test_scene_describes_the_polygon_and_its_reach(tmp_path, capsys):
    figure = tmp_path / "triangle.png"
    assert main(["scene", "--polygon", TRIANGLE, "--mass", "0.08", "--figure", str(figure), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    config = SceneConfig(object=ObjectConfig(vertices=parse_polygon(TRIANGLE)), box_mass=0.08)
    o, reach = summary["object"], summary["reach"]
    assert o["kind"] == "polygon" and o["name"].startswith("triangle") and "size_m" not in o
    np.testing.assert_allclose(o["vertices_m"], config.shape.vertices, atol=1e-6)
    assert o["area_m2"] == pytest.approx(math.sqrt(3) / 4 * 0.14**2, rel=1e-5)
    assert o["mass_kg"] == 0.08 and o["inertia_zz_kg_m2"] == pytest.approx(0.08 * 0.14**2 / 12, rel=1e-5)
    grasps = initial_grasp_candidates(build_scene(config), Config().search)
    assert reach["graspable"] and reach["reason"] == ""
    assert reach["contacts_per_finger"] == list(grasps.reachable) and min(grasps.reachable) > 0
    assert reach["initial_grasps"] == len(grasps.candidates) > 0
    assert reach["best_grasp_arclengths_m"] == list(grasps.candidates[0].arclengths)
    assert figure.stat().st_size > 10_000 and summary["figure"] == str(figure)


def test_scene_reports_an_object_the_hand_cannot_grasp_and_plan_refuses_it(tmp_path, capsys):
    assert main(["scene", "--polygon", TINY, "--figure", str(tmp_path / "tiny.png")]) == 0
    out = capsys.readouterr().out
    assert (
        "reach at the initial pose: [0, 1, 1, 0] corner-free contacts (every 0.02 m) per finger; the hand "
        "CANNOT grasp the object: finger(s) [0, 3] reach no corner-free contact at the initial pose"
    ) in out
    assert (tmp_path / "tiny.png").is_file()
    for args in (
        ["plan", "--goal", "0.3", "--polygon", TINY, "--out", str(tmp_path / "p")],
        ["demo", "--polygon", TINY, "--out", str(tmp_path / "d")],
        ["sweep", "--goals", "2", "--polygon", TINY, "--out", str(tmp_path / "s"), "--no-progress"],
    ):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert (
            "--polygon (scene.object.vertices): the hand cannot grasp the triangle (8 cm^2) at "
            "scene.initial_pose [0.0, 0.0, 0.0]: finger(s) [0, 3] reach no corner-free contact" in err
        )
    assert listing(tmp_path) == ["tiny.png"]


def test_scene_still_describes_the_box():
    parser = build_parser()
    from trajectotree.cli.scene_cmd import describe

    o = describe(build_scene(config_from_args(parser.parse_args(["scene", "--box-size", "0.16", "0.08"])).scene))
    assert o["kind"] == "box" and o["size_m"] == [0.16, 0.08] and o["name"] == "0.16 x 0.08 m box"
    assert o["inertia_zz_kg_m2"] == pytest.approx(0.05 * (0.16**2 + 0.08**2) / 12)


def float32_triples(html: str) -> bytes:
    """Every base64 payload of Meshcat's static page, decoded and joined (its msgpack messages)."""
    return b"".join(base64.b64decode(b) for b in re.findall(r"base64,([A-Za-z0-9+/=]+)", html))


def test_plan_playback_of_a_polygon_embeds_its_mesh(tmp_path):
    """The self-contained page carries the prism's vertex positions (float32 x, y, z in the
    object frame) in its own data, and loads nothing from elsewhere."""
    from trajectotree.execution.playback import write_pose_html

    config = Config(scene=SceneConfig(object=ObjectConfig(vertices=parse_polygon(TRIANGLE))))
    path = tmp_path / "triangle.html"
    write_pose_html(config, [0.0, 0.5], [(0, 0, 0), (0, 0.01, 0.2)], np.tile([0.25, 1.2], (2, 4)), path)
    html = path.read_text()
    data = float32_triples(html)
    for x, y in config.scene.shape.vertices:
        for z in (-0.025, 0.025):
            assert np.array([x, y, z], dtype=np.float32).tobytes() in data, (x, y, z)
    assert not re.search(r"<(script|link|img)[^>]*(src|href)=", html)  # every script inlined
    assert "object (planned pose)" in html


@pytest.mark.slow
def test_demo_plans_simulates_and_plays_back_a_triangle(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--polygon", TRIANGLE, "--goal", "0.3", "--segments", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["object"] == "triangle (85 cm^2)" and "rotate the triangle (85 cm^2) by +0.300 rad" in printed
    assert summary["plan"]["success"] and not summary["simulation"]["dropped"]
    assert "object held (ended within 3 deg and 5 mm" in printed
    data = float32_triples((out / "playback.html").read_text())
    shape = SceneConfig(object=ObjectConfig(vertices=parse_polygon(TRIANGLE))).shape
    assert all(np.array([x, y, 0.025], dtype=np.float32).tobytes() in data for x, y in shape.vertices)


def test_a_rectangle_given_as_a_polygon_is_described_as_the_box_it_is(capsys):
    """The 0.24 x 0.06 m bar, given by its corners (clockwise): box.sdf at the bar's size, not
    at scene.box_width x box_height."""
    assert main(["scene", "--polygon", "-0.12,-0.03 -0.12,0.03 0.12,0.03 0.12,-0.03", "--json"]) == 0
    o = json.loads(capsys.readouterr().out)["object"]
    assert o["kind"] == "box" and o["size_m"] == [0.24, 0.06] and o["name"] == "0.24 x 0.06 m box"
    assert o["inertia_zz_kg_m2"] == pytest.approx(0.05 * (0.24**2 + 0.06**2) / 12, rel=1e-12)


TWELVE_GON = " ".join(
    f"{0.065 * math.cos(2 * math.pi * (k + 0.5) / 12):.6f},{0.065 * math.sin(2 * math.pi * (k + 0.5) / 12):.6f}"
    for k in range(12)
)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--circle", "0"], "--circle (scene.object.circle_radius) = 0.0 is out of range; valid range: (0, 0.3]"),
        (["--circle", "-0.05"], "--circle (scene.object.circle_radius) = -0.05 is out of range"),
        (["--ellipse", "0.08", "-0.05"], "--ellipse (scene.object.ellipse_semi_axes[1]) = -0.05 is out of range"),
        (["--circle", "0.06", "--polygon", TRIANGLE], "--polygon and --circle both describe the object"),
        (["--ellipse", "0.08", "0.05", "--box-size", "0.2", "0.1"], "--box-size and --ellipse both describe"),
    ],
)
def test_bad_round_objects_exit_2_naming_the_value_and_write_nothing(args, message, tmp_path, capsys):
    assert main(["plan", "--goal", "0.1", *args, "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert listing(tmp_path) == []


def test_round_objects_are_polygonized_with_blunt_corners_the_hand_can_grasp(capsys):
    parser = build_parser()
    for args, noun in (
        (["--circle", "0.06"], "disc of radius 0.06 m"),
        (["--ellipse", "0.08", "0.05"], "ellipse of semi-axes 0.08 x 0.05 m"),
        (["--polygon", TWELVE_GON], "12-gon"),
    ):
        config = config_from_args(parser.parse_args(["scene", *args]))
        grasps = initial_grasp_candidates(build_scene(config.scene), config.search)
        assert grasps.refusal is None and len(grasps.candidates) > 0, args  # the 12-gon was refused before
        assert main(["scene", *args]) == 0
        assert noun in capsys.readouterr().out
