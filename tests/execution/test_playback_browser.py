"""The self-contained Meshcat HTML playback, opened in Debian's Chromium (apt
package `chromium`, installed by .ci/run) through playwright, with software WebGL.
No browser is downloaded: playwright drives /usr/bin/chromium."""

import dataclasses
import io
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from trajectotree.config import Config, SceneConfig
from trajectotree.config.executor import Executor
from trajectotree.execution.force_arrows import ARROW_HEAD, ARROW_Z
from trajectotree.execution.meshcat_scene import VIEW_HALF_WIDTH, finger_css
from trajectotree.execution.playback import write_plan_html
from trajectotree.execution.playback_page import finger_labels
from trajectotree.execution.reference import Reference, static_hold_reference
from trajectotree.execution.simulate import simulate_reference
from trajectotree.figures.legend import finger_rgb
from trajectotree.figures.run import arrow_newtons_per_cm, arrow_scale_text, force_arrow
from trajectotree.scene.plant import NUM_FINGERS, build_scene

pytestmark = pytest.mark.slow  # a headless browser (seconds per test)
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-default-apps",
    "--disable-sync",
    "--disable-extensions",
    "--no-first-run",
    "--mute-audio",
]
VIEWPORT = {"width": 640, "height": 640}
WIDE = {"width": 1200, "height": 600}  # a browser window wider than tall


@pytest.fixture(scope="module")
def drop_run(tmp_path_factory):
    """Playback of a real run that moves the box: the hand lets go (zero torque) and
    the box slides down between the fingers for 0.3 s; its reference and result."""
    config = Config()
    config = dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))
    reference = static_hold_reference(
        build_scene(config.scene), (0.56, 0.14, 0.26, 0.44), min_normal_force=1.0, duration=0.3
    )
    path = tmp_path_factory.mktemp("playback") / "drop.html"
    result = simulate_reference(reference, config, executor=Executor.NONE, html_path=path)
    assert result.dropped and result.x[-1, 1] < -0.05  # the box moved well within the view
    return SimpleNamespace(path=path, reference=reference, result=result, config=config)


@pytest.fixture(scope="module")
def drop_html(drop_run):
    return drop_run.path


@pytest.fixture(scope="module")
def plan_reference():
    """A planned (kinematic) motion: the grasped box lifted by 4 cm and turned by 0.3 rad
    in 1 s, joint angles by IK at both ends, each finger pushing 1 N or more."""
    holds = [
        static_hold_reference(
            build_scene(SceneConfig(initial_pose=pose)), (0.56, 0.14, 0.26, 0.44), min_normal_force=1.0, duration=1.0
        )
        for pose in ((0, 0, 0), (0, 0.04, 0.3))
    ]
    return Reference(
        t=np.array([0.0, 1.0]),
        **{name: np.stack([getattr(h, name)[0] for h in holds]) for name in ("x", "q", "p_WF", "v_WF", "f_W")},
    )


@pytest.fixture(scope="module")
def plan_html(tmp_path_factory, plan_reference):
    """Playback of plan_reference."""
    path = tmp_path_factory.mktemp("playback") / "plan.html"
    write_plan_html(plan_reference, Config(), path)
    return path


class Page:
    """A Chromium page on a local HTML file that records every request and page error."""

    def __init__(self, browser, html: Path, viewport=VIEWPORT):
        self.requests, self.errors = [], []
        self.page = browser.new_page(viewport=viewport)
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.goto(html.resolve().as_uri())
        for _ in range(100):  # up to 20 s for the viewer; a page error (e.g. no WebGL) ends the wait
            if self.errors or self.page.evaluate("() => !!(window.viewer && window.viewer.animator)"):
                break
            self.page.wait_for_timeout(200)
        assert self.errors == [], f"page errors: {self.errors}"

    def frame_at(self, t: float) -> np.ndarray:
        """RGB screenshot (H, W, 3) of the paused animation at time t."""
        from PIL import Image

        self.page.evaluate(f"() => {{ viewer.animator.pause(); viewer.animator.seek({t}); }}")
        self.page.wait_for_timeout(400)
        return np.asarray(Image.open(io.BytesIO(self.page.screenshot())).convert("RGB")).astype(int)


def to_pixel(p, viewport=VIEWPORT) -> tuple[int, int]:
    """(row, column) where the centred planar view draws the point p (x, y) of W."""
    scale = min(viewport["width"], viewport["height"]) / (2 * VIEW_HALF_WIDTH)  # px per m
    return round(viewport["height"] / 2 - scale * p[1]), round(viewport["width"] / 2 + scale * p[0])


# The scene's colours: each finger's, the box's blue, the links' greys, the white background.
SCENE_COLORS = [np.multiply(255, finger_rgb(i)) for i in range(NUM_FINGERS)] + [
    (51, 115, 204),
    (89, 89, 102),
    (115, 115, 128),
    (255, 255, 255),
]


def nearest_color(rgb: np.ndarray, row: int, col: int) -> int:
    """Index into SCENE_COLORS of the colour nearest the median of the 3 x 3 pixels around (row, col)."""
    pixel = np.median(rgb[row - 1 : row + 2, col - 1 : col + 2].reshape(-1, 3), axis=0)
    return int(np.argmin([np.linalg.norm(pixel - np.asarray(c)) for c in SCENE_COLORS]))


def box_pixels(rgb: np.ndarray) -> np.ndarray:
    """Mask of the box's blue (SDF diffuse 0.20 0.45 0.80); links are grey, tips orange,
    the plan outline green, the background white."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (b > 150) & (b - r > 80) & (b - g > 30)


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.fail("Debian's chromium is missing: `apt-get install chromium` (.ci/run does it)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield browser
        browser.close()


class Pages:
    """The module's one open page: a test asks for a file in a window size, and consecutive tests on
    the same file and size share its page (loading the viewer takes seconds; the tests below are
    grouped by page). Each test seeks the animation itself. The page it replaces is closed: an
    open page keeps animating, rendering in software on the CPU, and would slow every later test."""

    def __init__(self, browser):
        self.browser, self.key, self.page = browser, None, None

    def open(self, html: Path, viewport=VIEWPORT) -> Page:
        key = (html.resolve(), viewport["width"], viewport["height"])
        if key != self.key:
            self.close()
            self.key, self.page = key, Page(self.browser, html, viewport)
        return self.page

    def close(self) -> None:
        if self.page is not None:
            self.page.page.context.close()
        self.key, self.page = None, None


@pytest.fixture(scope="module")
def pages(browser):
    opened = Pages(browser)
    yield opened
    opened.close()


# ---- the simulated run that drops the box (drop.html) -------------------------------------------


def test_html_playback_renders_offline_and_animates(pages, drop_html):
    page = pages.open(drop_html)
    duration = page.page.evaluate("() => viewer.animator.duration")
    assert duration == pytest.approx(0.3, abs=0.05)
    start, later = page.frame_at(0.0), page.frame_at(0.25)
    # offline: the only request is the file itself; nothing failed on the page
    assert page.requests == [drop_html.resolve().as_uri()]
    assert page.errors == []
    # the scene renders: the box covers thousands of pixels, the frame is not blank
    mask0, mask1 = box_pixels(start), box_pixels(later)
    assert mask0.sum() > 2000 and mask1.sum() > 2000
    assert len(np.unique(start.reshape(-1, 3), axis=0)) > 50
    # +y is up: the box starts in the middle of the view and is lower (larger row) later
    rows0, cols0 = np.nonzero(mask0)
    rows1, cols1 = np.nonzero(mask1)
    assert abs(rows0.mean() - VIEWPORT["height"] / 2) < 20 and abs(cols0.mean() - VIEWPORT["width"] / 2) < 20
    assert rows1.mean() - rows0.mean() > 30


def test_simulated_playback_draws_the_simulated_forces_as_arrows(pages, drop_run):
    """At t = 0.25 s (a frame of the playback and a sample of the log): each finger pushing 0.02 N
    or more has its arrow shown from its fingertip along its logged force at the stated scale, the
    others hidden; the frame has both kinds."""
    page = pages.open(drop_run.path)
    page.frame_at(0.25)
    arrows = page.page.evaluate(
        """() => [0, 1, 2, 3].map((i) => {
             const find = (path) => viewer.scene_tree.find(["forces", "finger" + i, ...path]).object;
             const group = find([]), shaft = find(["shaft", "<object>"]);
             return {visible: group.visible, position: group.position.toArray(), angle: group.rotation.z,
                     shaft: shaft.scale.x};
           })"""
    )
    result, scale = drop_run.result, arrow_newtons_per_cm(drop_run.reference.f_W)
    k = int(np.argmin(abs(result.t - 0.25)))
    assert result.t[k] == pytest.approx(0.25)
    scene = build_scene(drop_run.config.scene)
    tips = scene.fingertip_positions(result.q[k])
    shown = []
    for i, arrow in enumerate(arrows):
        expected = force_arrow(tips[i], result.f_W[k, i], scene.tip_radius, scale)
        shown.append(arrow["visible"])
        if expected is None:
            assert not arrow["visible"], f"finger {i} pushes nothing: no arrow"
            continue
        start, end = expected
        length = np.linalg.norm(end - start)
        assert arrow["visible"], f"finger {i}"
        np.testing.assert_allclose(arrow["position"], [*start, ARROW_Z], atol=1e-6)
        assert arrow["angle"] == pytest.approx(np.arctan2(end[1] - start[1], end[0] - start[0]), abs=1e-6)
        assert arrow["shaft"] == pytest.approx(length - min(ARROW_HEAD, length / 2), abs=1e-6)
    assert any(shown) and not all(shown)


def test_page_shows_title_time_readout_drop_and_legend_and_centres_the_view(pages, drop_run):
    """On a wide window: the tab title, the time readout (with the drop marked), the legend,
    read from the page and found in its screenshot, and the hand centred (not in the left half)."""
    drop_html = drop_run.path
    page = pages.open(drop_html, viewport=WIDE)
    assert page.page.title() == "TrajectoTree: simulated run"
    duration = page.page.evaluate("() => viewer.animator.duration")
    drop = drop_run.result.drop_time_s
    halfway = round(drop / 2, 2)
    before = page.frame_at(halfway)
    assert page.page.inner_text("#tt-time") == f"t = {halfway:.2f} s of {duration:.2f} s"
    assert page.page.inner_text("#tt-drop-note") == f"box drops at {drop:.2f} s"
    after = page.frame_at(0.25)
    assert page.page.inner_text("#tt-time") == f"t = 0.25 s of {duration:.2f} s"
    assert page.page.inner_text("#tt-drop-note") == f"box dropped at {drop:.2f} s"
    legend = page.page.inner_text("#tt-legend").splitlines()
    scale = arrow_newtons_per_cm(drop_run.reference.f_W)
    assert scale == 0.5  # the reference's largest force, 1.25 N, is 2.5 cm long
    assert legend == [
        "fingertips 0 1 2 3 (numbered at their bases)",
        "box",
        "planned box pose (outline)",
        "finger links",
        f"arrow: simulated force of each finger on the box, {arrow_scale_text(scale)}",
    ]
    # in the screenshot: the overlay and legend are drawn inside the window, the swatches in their colours
    for selector in ("#tt-overlay", "#tt-legend"):
        b = page.page.locator(selector).bounding_box()
        assert (
            b["x"] >= 0
            and b["y"] >= 0
            and b["x"] + b["width"] <= WIDE["width"]
            and b["y"] + b["height"] <= WIDE["height"]
        ), selector
    swatch = page.page.locator(".tt-swatch").first.bounding_box()
    np.testing.assert_allclose(
        after[int(swatch["y"] + swatch["height"] / 2), int(swatch["x"] + swatch["width"] / 2)], [51, 115, 204], atol=12
    )
    drop_mark = page.page.locator("#tt-drop").bounding_box()
    assert after[int(drop_mark["y"] + drop_mark["height"] / 2), int(drop_mark["x"] + 1)][0] > 180  # red
    # the hand is centred: the box starts in the middle of the wide window
    rows, cols = np.nonzero(box_pixels(before))
    assert abs(cols.mean() - WIDE["width"] / 2) < 25 and abs(rows.mean() - WIDE["height"] / 2) < 25


# ---- the planned motion (plan.html): fingers coloured, numbered, their forces drawn as arrows ------


def test_plan_playback_shows_the_planned_motion(pages, plan_html):
    page = pages.open(plan_html)
    assert page.page.evaluate("() => viewer.animator.duration") == pytest.approx(1.0, abs=0.05)
    start, end = box_pixels(page.frame_at(0.0)), box_pixels(page.frame_at(1.0))
    assert page.requests == [plan_html.resolve().as_uri()] and page.errors == []
    rows0, _ = np.nonzero(start)
    rows1, _ = np.nonzero(end)
    pixels_per_m = VIEWPORT["height"] / (2 * VIEW_HALF_WIDTH)
    assert rows0.mean() - rows1.mean() == pytest.approx(0.04 * pixels_per_m, abs=8)  # lifted 4 cm (+y up)


def test_plan_page_is_titled_and_has_no_drop_marker(pages, plan_html):
    page = pages.open(plan_html)
    assert page.page.title() == "TrajectoTree: planned trajectory"
    page.frame_at(0.5)
    assert page.page.inner_text("#tt-time") == "t = 0.50 s of 1.00 s"
    assert page.page.locator("#tt-drop").count() == 0
    assert page.page.inner_text("#tt-legend").splitlines()[1] == "box (planned pose)"


def test_plan_playback_colours_each_fingertip_and_draws_its_planned_force(pages, plan_html, plan_reference):
    """At t = 0: each fingertip sphere in its finger's colour (figures.run.FINGER_COLORS), each
    finger's planned force (1 N or more) as an arrow in that colour from the fingertip along the
    force, as long as the stated scale says: its colour at the arrow's middle, not past its end."""
    page = pages.open(plan_html)
    rgb = page.frame_at(0.0)
    scale = arrow_newtons_per_cm(plan_reference.f_W)
    legend = page.page.inner_text("#tt-legend").splitlines()
    assert legend[-1] == f"arrow: planned force of each finger on the box, {arrow_scale_text(scale)}"
    tip_radius = build_scene().tip_radius
    for i in range(NUM_FINGERS):
        tip, f = plan_reference.p_WF[0, i], plan_reference.f_W[0, i]
        side = np.array([-f[1], f[0]]) / np.hypot(*f)  # beside the arrow, on the sphere
        assert nearest_color(rgb, *to_pixel(tip + 0.6 * tip_radius * side)) == i, f"finger {i}'s tip"
        start, end = force_arrow(tip, f, tip_radius, scale)
        direction = (end - start) / np.linalg.norm(end - start)
        assert np.linalg.norm(end - start) > 0.02  # long enough to sample beyond the fingertip
        assert nearest_color(rgb, *to_pixel(start + 0.6 * (end - start))) == i, f"finger {i}'s arrow"
        assert nearest_color(rgb, *to_pixel(end + 0.006 * direction)) != i, f"finger {i}'s arrow ends there"
    dots = page.page.locator(".tt-dot").evaluate_all("(dots) => dots.map((d) => getComputedStyle(d).backgroundColor)")
    assert dots == [finger_css(i) for i in range(NUM_FINGERS)]


@pytest.mark.parametrize("viewport", [VIEWPORT, WIDE])
def test_finger_numbers_sit_outside_the_bases_in_the_fingers_colours(pages, plan_html, viewport):
    page = pages.open(plan_html, viewport=viewport)
    page.frame_at(0.5)
    scene = build_scene()
    for k, (text, color, x, y) in enumerate(finger_labels(scene.plant, scene.hand, scene.hand_description)):
        label = page.page.locator(f"#tt-label-{k}")
        assert label.inner_text() == text == str(k)
        assert label.evaluate("(e) => getComputedStyle(e).color") == color == finger_css(k)
        box = label.bounding_box()
        row, col = to_pixel((x, y), viewport)
        assert abs(box["x"] + box["width"] / 2 - col) < 2 and abs(box["y"] + box["height"] / 2 - row) < 2
        base = scene.fingers[k].p_W_base
        assert np.hypot(x, y) == pytest.approx(np.hypot(*base) + 0.03)
        assert base[0] * y - base[1] * x == pytest.approx(0.0, abs=1e-12)  # radially outside the base


# ---- a polygon ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def triangle_html(tmp_path_factory):
    """Playback of a run with an equilateral triangle (side 0.14 m, apex up) that the hand lets go."""
    from trajectotree.config import ObjectConfig
    from trajectotree.search.initial_grasp import initial_grasp_candidates

    side = 0.14
    r = side / np.sqrt(3)
    vertices = tuple(
        (r * np.cos(np.pi / 2 + 2 * np.pi * k / 3), r * np.sin(np.pi / 2 + 2 * np.pi * k / 3)) for k in range(3)
    )
    config = Config(scene=SceneConfig(object=ObjectConfig(vertices=vertices)))
    config = dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))
    scene = build_scene(config.scene)
    grasp = initial_grasp_candidates(scene, config.search).candidates[0]
    reference = static_hold_reference(scene, grasp.arclengths, min_normal_force=1.0, duration=0.3)
    path = tmp_path_factory.mktemp("playback") / "triangle.html"
    result = simulate_reference(reference, config, executor=Executor.NONE, html_path=path)
    assert result.dropped
    return path, side, result.drop_time_s


def test_polygon_playback_draws_the_polygon(pages, triangle_html):
    """The triangle's prism is drawn as a triangle: its area in pixels, centred, apex up (more of
    it below its centroid than above: 5/9), and the page calls it the object."""
    path, side, drop = triangle_html
    page = pages.open(path)
    mask = box_pixels(page.frame_at(0.0))
    assert page.requests == [path.resolve().as_uri()] and page.errors == []
    pixels_per_m = VIEWPORT["height"] / (2 * VIEW_HALF_WIDTH)
    area = np.sqrt(3) / 4 * side**2 * pixels_per_m**2
    assert mask.sum() == pytest.approx(area, rel=0.12)  # fingertips cover a little of it
    rows, cols = np.nonzero(mask)
    assert abs(cols.mean() - VIEWPORT["width"] / 2) < 10
    centroid_row = VIEWPORT["height"] / 2
    assert np.sum(rows > centroid_row) / len(rows) == pytest.approx(5 / 9, abs=0.05)
    assert page.page.inner_text("#tt-legend").splitlines()[1:3] == ["object", "planned object pose (outline)"]
    page.frame_at(0.25)
    assert page.page.inner_text("#tt-drop-note") == f"object dropped at {drop:.2f} s"


# ---- a replanned run (playback.html): one Simulator, its playback as any other's -------------------


@pytest.fixture(scope="module")
def replanned_run(tmp_path_factory):
    """A two-segment plan (0.3 rad) executed with replanning in a world of friction 0.3, with a tracking
    threshold that makes it replan at its node (1.2 s), from the measured state (the next node is the goal):
    its playback.html, GIF and result."""
    from trajectotree.config import with_values
    from trajectotree.execution.run import run_simulation
    from trajectotree.planning.planners import plan

    result = plan(goal=0.3, config=with_values(Config(), {"search.num_nodes": 3}))
    assert result.success, result.status
    tight = {"controller.replan.theta_error": 1e-4, "controller.replan.position_error": 1e-5}
    once = {"controller.replan.max_replans": 1, "controller.replan.measured_start_on_error": True}
    config = with_values(result.config, tight | once)
    folder = tmp_path_factory.mktemp("playback")
    path, gif = folder / "playback.html", folder / "replan.gif"
    run = run_simulation(plan=result, config=config, executor="grasp-replan", sim_mu=0.3, html_path=path, gif_path=gif)
    assert len(run.replans) == 1 and path.exists() and gif.stat().st_size > 0
    return SimpleNamespace(path=path, result=run, plan=result)


def test_a_replanned_run_writes_its_playback(replanned_run, pages):
    page = pages.open(replanned_run.path)
    run, (event,) = replanned_run.result, replanned_run.result.replans
    assert page.requests == [replanned_run.path.resolve().as_uri()] and page.errors == []
    # the whole run in one recording: past the first plan's end by the hold while the planner ran
    duration = page.page.evaluate("() => viewer.animator.duration")
    assert duration == pytest.approx(run.t[-1], abs=0.05)
    assert run.t[-1] >= replanned_run.plan.trajectory.t[-1] + event.latency_s
    # the box is drawn where the simulation had it, before the replan and at the end
    for t in (0.5 * event.time_s, run.t[-1]):
        i = int(np.argmin(np.abs(run.t - t)))
        rows, cols = np.nonzero(box_pixels(page.frame_at(run.t[i])))
        assert rows.size > 2000
        row, col = to_pixel(run.x[i, :2])
        assert abs(np.mean(rows) - row) < 6 and abs(np.mean(cols) - col) < 6, (t, np.mean(rows), np.mean(cols))
