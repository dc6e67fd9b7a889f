"""Watching a run in space (issue 37 item 3): `trajectotree demo --hand fingerpro4` plans a 34 deg turn about the
horizontal x axis, executes it and writes the plan, the run, playback.html, keyframes.png, forces.png and run.gif;
its playback.html opened in Debian's Chromium (as test_playback_browser.py, whose page helper it uses) shows the
hand and cube as simulated, each fingertip and each finger's simulated force arrow in the finger's colour, and a
legend that says the arrows are the simulated forces."""

import colorsys
import contextlib
import io
import json
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image
from test_playback_browser import CHROMIUM, CHROMIUM_ARGS, Page

from trajectotree.cli import main
from trajectotree.execution.force_arrows import ARROW_HEAD
from trajectotree.execution.meshcat_scene import CUBE_ALPHA, finger_css
from trajectotree.figures.legend import arrow_newtons_per_cm, arrow_scale_text, finger_rgb, force_arrow
from trajectotree.figures.space import finger_polylines
from trajectotree.scene.spatial import build_space_scene

pytestmark = pytest.mark.slow  # a plan, a run and a headless browser
GOAL = ["--goal-rpy", "0.6", "0", "0"]  # rad: 34 deg about x, the demo's quarter turn made short
FILES = ["plan.json", "plan.npz", "keyframes.png", "sim.json", "sim.npz", "playback.html", "forces.png", "run.gif"]
T = 1.5  # s, a frame of the playback and a sample of the log, after the switch (every finger pushing)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo in space, its folder, what it printed, its run and plan arrays and the scene."""
    out = tmp_path_factory.mktemp("demo3d") / "demo"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["demo", "--hand", "fingerpro4", *GOAL, "--out", str(out)])
    with np.load(out / "sim.npz") as npz:
        sim = {name: npz[name] for name in npz.files}
    with np.load(out / "plan.npz") as npz:
        plan = {name: npz[name] for name in npz.files}
    scene = build_space_scene("fingerpro4", mu=0.7, gravity=9.81)
    return SimpleNamespace(code=code, out=out, printed=printed.getvalue(), sim=sim, plan=plan, scene=scene)


def test_the_demo_in_space_plans_executes_and_writes_its_files(demo):
    assert demo.code == 0
    summary = json.loads((demo.out / "summary.json").read_text())
    assert summary["files"] == [*FILES, "summary.json"]
    assert sorted(p.name for p in demo.out.iterdir() if not p.name.startswith(".")) == sorted(summary["files"])
    assert summary["plan"]["success"] and summary["plan"]["physics_check_passed"]
    run = json.loads((demo.out / "sim.json").read_text())
    assert run == summary["simulation"] and not run["dropped"] and run["within_15deg"]
    # what the planar demo prints: the times of each stage and the run's errors
    for start in ("TrajectoTree demo in space: turn the cube by 34.4 deg", "  contact search", "  CITO (IPOPT)"):
        assert start in demo.printed
    assert f"held; final orientation error {run['final_orientation_error_deg']:.2f} deg" in demo.printed
    assert f"open {demo.out / 'playback.html'} in a browser" in demo.printed
    F = demo.scene.num_fingers
    assert demo.sim["x"].shape[1] == 7 and demo.sim["f_W"].shape[1:] == (F, 3)
    gif = Image.open(demo.out / "run.gif")
    assert gif.format == "GIF" and gif.n_frames >= 20  # 10 frames a second of a 2.5 s run
    assert Image.open(demo.out / "forces.png").size[1] > Image.open(demo.out / "forces.png").size[0] / 2


# ---- the playback page in a browser ---------------------------------------------------------------


@pytest.fixture(scope="module")
def page(demo):
    if not CHROMIUM.exists():
        pytest.fail("Debian's chromium is missing: `apt-get install chromium` (.ci/run does it)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        opened = Page(browser, demo.out / "playback.html")
        yield opened
        opened.page.context.close()
        browser.close()


def _arrows(page, num_fingers: int) -> list[dict]:
    """Each finger's arrow as the page holds it: shown or not, its origin and x axis in W, its shaft's length."""
    return page.page.evaluate(
        """(F) => [...Array(F).keys()].map((i) => {
             const find = (path) => viewer.scene_tree.find(["forces", "finger" + i, ...path]).object;
             const group = find([]), shaft = find(["shaft", "<object>"]);
             const x = new MeshCat.THREE.Vector3(1, 0, 0).applyQuaternion(group.quaternion);
             return {visible: group.visible, position: group.position.toArray(), x: x.toArray(),
                     shaft: shaft.scale.x};
           })""",
        num_fingers,
    )


def _pixels(page, points) -> list[tuple[int, int]]:
    """(row, column) where the page's camera draws each point (3,) of W (as the page places its finger numbers)."""
    return page.page.evaluate(
        """(points) => {
             const c = viewer.camera, root = viewer.scene_tree.object, r = viewer.dom_element.getBoundingClientRect();
             c.updateMatrixWorld(); root.updateMatrixWorld();
             return points.map((p) => {
               const v = root.localToWorld(new MeshCat.THREE.Vector3(...p)).project(c);
               return [Math.round(r.top + (1 - v.y) / 2 * r.height), Math.round(r.left + (v.x + 1) / 2 * r.width)];
             });
           }""",
        [list(map(float, p)) for p in points],
    )


def _finger_of(rgb: np.ndarray, row: int, col: int) -> int | None:
    """The finger whose colour's hue the median of the 3 x 3 pixels around (row, col) has (within 12 deg; the
    scene's shading changes brightness, not hue), None for a grey, white or dark pixel."""
    pixel = np.median(rgb[row - 1 : row + 2, col - 1 : col + 2].reshape(-1, 3), axis=0) / 255
    hue, saturation, value = colorsys.rgb_to_hsv(*pixel)
    if saturation < 0.35 or value < 0.2:
        return None
    distance = [abs(hue - colorsys.rgb_to_hsv(*finger_rgb(i))[0]) for i in range(4)]
    distance = [min(d, 1 - d) for d in distance]
    i = int(np.argmin(distance))
    return i if distance[i] < 12 / 360 else None


def test_the_page_is_offline_titled_and_its_legend_says_the_arrows_are_simulated(page, demo):
    assert page.requests == [(demo.out / "playback.html").resolve().as_uri()] and page.errors == []
    assert page.page.title() == "TrajectoTree: simulated run"
    duration = page.page.evaluate("() => viewer.animator.duration")
    assert duration == pytest.approx(demo.sim["t"][-1], abs=0.05)
    page.frame_at(T)
    assert page.page.inner_text("#tt-time") == f"t = {T:.2f} s of {duration:.2f} s"
    scale = arrow_newtons_per_cm(demo.plan["f_W"])  # the plan's scale, as the plan's page and the GIF
    assert page.page.inner_text("#tt-legend").splitlines() == [
        "fingertips 0 1 2 3 (numbered at their bases)",
        "cube",
        "planned cube pose (edges)",
        "finger links",
        f"arrow: simulated force of each finger on the cube, {arrow_scale_text(scale)}",
    ]
    dots = page.page.locator(".tt-dot").evaluate_all("(dots) => dots.map((d) => getComputedStyle(d).backgroundColor)")
    assert dots == [finger_css(i) for i in range(4)]


def test_each_arrow_is_the_simulated_force_of_its_finger(page, demo):
    """At T: each finger's arrow from its simulated fingertip sphere's surface along its logged force on the cube,
    as long as the stated scale says (figures.legend.force_arrow, the plane's rule)."""
    page.frame_at(T)
    k = int(np.argmin(abs(demo.sim["t"] - T)))
    assert demo.sim["t"][k] == pytest.approx(T)
    scene, scale = demo.scene, arrow_newtons_per_cm(demo.plan["f_W"])
    tips = finger_polylines(scene, demo.sim["q"][k].reshape(scene.num_fingers, -1))[:, -1]
    for i, arrow in enumerate(_arrows(page, scene.num_fingers)):
        start, end = force_arrow(tips[i], demo.sim["f_W"][k, i], scene.tip_radius, scale)  # every finger pushes
        length = np.linalg.norm(end - start)
        assert arrow["visible"], f"finger {i}"
        np.testing.assert_allclose(arrow["position"], start, atol=1e-6)
        np.testing.assert_allclose(arrow["x"], (end - start) / length, atol=1e-6)
        assert arrow["shaft"] == pytest.approx(length - min(ARROW_HEAD, length / 2), abs=1e-6)


def test_the_cube_is_drawn_see_through_where_it_was_simulated_and_the_plan_as_its_edges(page, demo):
    page.frame_at(T)
    k = int(np.argmin(abs(demo.sim["t"] - T)))
    state = page.page.evaluate(
        """() => {
             const cube = viewer.scene_tree.find(["drake", "visualizer", "box", "box"]).object;
             const ghost = viewer.scene_tree.find(["plan", "box"]).object;
             let material = null;
             cube.traverse((o) => { if (o.material && material === null) material = o.material; });
             return {cube: cube.position.toArray(), turn: cube.quaternion.toArray(),
                     opacity: material.opacity, transparent: material.transparent,
                     ghost: ghost.position.toArray(), ghost_turn: ghost.quaternion.toArray()};
           }"""
    )
    assert state["opacity"] == pytest.approx(CUBE_ALPHA) and state["transparent"]
    # the cube where the simulation had it, the planned cube's edges at the planned pose (three.js writes a
    # quaternion x, y, z, w)
    for (position, turn), x in (
        ((state["cube"], state["turn"]), demo.sim["x"][k]),
        ((state["ghost"], state["ghost_turn"]), demo.sim["x_plan"][k]),
    ):
        np.testing.assert_allclose(position, x[4:], atol=1e-6)
        assert abs(np.dot(turn, [*x[1:4], x[0]])) / np.linalg.norm(x[:4]) == pytest.approx(1.0, abs=1e-6)
    assert 2 * np.arccos(abs(demo.sim["x"][k, 0])) > np.radians(20)  # turned: the check above sees the turn


def test_the_fingertips_and_arrows_are_drawn_in_the_fingers_colours(page, demo):
    """In the screenshot at T with the cube hidden (its see-through faces tint what lies behind them): each
    fingertip sphere's centre and the middle of each arrow's shaft in that finger's colour."""
    page.frame_at(T)
    page.page.evaluate(
        "() => { viewer.scene_tree.find(['drake', 'visualizer', 'box']).object.visible = false; viewer.set_dirty(); }"
    )
    rgb = page.frame_at(T)
    k = int(np.argmin(abs(demo.sim["t"] - T)))
    scene = demo.scene
    tips = finger_polylines(scene, demo.sim["q"][k].reshape(scene.num_fingers, -1))[:, -1]
    arrows = _arrows(page, scene.num_fingers)
    middles = [np.add(a["position"], np.multiply(a["x"], a["shaft"] / 2)) for a in arrows]
    for i, (tip, middle) in enumerate(zip(_pixels(page, tips), _pixels(page, middles))):
        assert _finger_of(rgb, *tip) == i, f"finger {i}'s fingertip"
        assert _finger_of(rgb, *middle) == i, f"finger {i}'s arrow"
    page.page.evaluate(
        "() => { viewer.scene_tree.find(['drake', 'visualizer', 'box']).object.visible = true; viewer.set_dirty(); }"
    )


def test_a_live_meshcat_shows_the_run_in_space_and_changes_nothing_in_it(demo):
    """simulate --meshcat's path (MeshcatVisualizer and the arrows in the Diagram, in real time): Meshcat holds the
    hand, the cube, the plan's edges and each finger's arrow, and the run logs what the demo's run logged."""
    from trajectotree.config import config_from_dict
    from trajectotree.execution.meshcat_scene import start_meshcat
    from trajectotree.execution.space_control import SpaceReference
    from trajectotree.execution.space_run import simulate_space

    config = config_from_dict(json.loads((demo.out / "plan.json").read_text())["config"])
    meshcat = start_meshcat()
    run = simulate_space(SpaceReference.from_arrays(demo.plan), config, demo.scene, meshcat=meshcat)
    paths = ["/drake/visualizer/box", "/drake/visualizer/fingerpro4", "/plan/box"]
    assert all(meshcat.HasPath(p) for p in paths + [f"/forces/finger{i}" for i in range(demo.scene.num_fingers)])
    for name in run.ARRAYS:
        np.testing.assert_array_equal(getattr(run, name), demo.sim[name], err_msg=name)
