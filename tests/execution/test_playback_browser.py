"""The self-contained Meshcat HTML playback, opened in Debian's Chromium (apt
package `chromium`, installed by .ci/run) through playwright, with software WebGL.
No browser is downloaded: playwright drives /usr/bin/chromium."""

import dataclasses
import io
from pathlib import Path

import numpy as np
import pytest

from trajectotree.config import Config, SceneConfig
from trajectotree.execution.playback import VIEW_HALF_WIDTH, write_plan_html
from trajectotree.execution.reference import Reference, static_hold_reference
from trajectotree.execution.simulate import simulate_reference
from trajectotree.scene.plant import build_scene

pytestmark = pytest.mark.slow  # a headless browser per test (seconds each)
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
def drop_html(tmp_path_factory):
    """Playback of a real run that moves the box: the hand lets go (zero torque) and
    the box slides down between the fingers for 0.3 s."""
    config = Config()
    config = dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))
    reference = static_hold_reference(
        build_scene(config.scene), (0.56, 0.14, 0.26, 0.44), min_normal_force=1.0, duration=0.3
    )
    path = tmp_path_factory.mktemp("playback") / "drop.html"
    result = simulate_reference(reference, config, controlled=False, html_path=path)
    assert result.dropped and result.x[-1, 1] < -0.05  # the box moved well within the view
    drop_times[path] = result.drop_time_s
    return path


drop_times: dict[Path, float] = {}  # drop_html -> the run's drop time, s


@pytest.fixture(scope="module")
def plan_html(tmp_path_factory):
    """Playback of a planned (kinematic) motion: the grasped box lifted by 4 cm and
    turned by 0.3 rad in 1 s, joint angles by IK at both ends."""
    holds = [
        static_hold_reference(
            build_scene(SceneConfig(initial_pose=pose)), (0.56, 0.14, 0.26, 0.44), min_normal_force=1.0, duration=1.0
        )
        for pose in ((0, 0, 0), (0, 0.04, 0.3))
    ]
    plan = Reference(
        t=np.array([0.0, 1.0]),
        **{name: np.stack([getattr(h, name)[0] for h in holds]) for name in ("x", "q", "p_WF", "v_WF", "f_W")},
    )
    path = tmp_path_factory.mktemp("playback") / "plan.html"
    write_plan_html(plan, Config(), path)
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


def test_html_playback_renders_offline_and_animates(browser, drop_html):
    page = Page(browser, drop_html)
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


def test_plan_playback_shows_the_planned_motion(browser, plan_html):
    page = Page(browser, plan_html)
    assert page.page.evaluate("() => viewer.animator.duration") == pytest.approx(1.0, abs=0.05)
    start, end = box_pixels(page.frame_at(0.0)), box_pixels(page.frame_at(1.0))
    assert page.requests == [plan_html.resolve().as_uri()] and page.errors == []
    rows0, _ = np.nonzero(start)
    rows1, _ = np.nonzero(end)
    pixels_per_m = VIEWPORT["height"] / (2 * VIEW_HALF_WIDTH)
    assert rows0.mean() - rows1.mean() == pytest.approx(0.04 * pixels_per_m, abs=8)  # lifted 4 cm (+y up)


def test_page_shows_title_time_readout_drop_and_legend_and_centres_the_view(browser, drop_html):
    """On a wide window: the tab title, the time readout (with the drop marked), the legend,
    read from the page and found in its screenshot, and the hand centred (not in the left half)."""
    page = Page(browser, drop_html, viewport=WIDE)
    assert page.page.title() == "TrajectoTree: simulated run"
    duration = page.page.evaluate("() => viewer.animator.duration")
    drop = drop_times[drop_html]
    halfway = round(drop / 2, 2)
    before = page.frame_at(halfway)
    assert page.page.inner_text("#tt-time") == f"t = {halfway:.2f} s of {duration:.2f} s"
    assert page.page.inner_text("#tt-drop-note") == f"box drops at {drop:.2f} s"
    after = page.frame_at(0.25)
    assert page.page.inner_text("#tt-time") == f"t = 0.25 s of {duration:.2f} s"
    assert page.page.inner_text("#tt-drop-note") == f"box dropped at {drop:.2f} s"
    legend = page.page.inner_text("#tt-legend").splitlines()
    assert legend == ["box", "planned box pose (outline)", "fingers 0-3: links (grey), fingertips (orange)"]
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


def test_plan_page_is_titled_and_has_no_drop_marker(browser, plan_html):
    page = Page(browser, plan_html)
    assert page.page.title() == "TrajectoTree: planned trajectory"
    page.frame_at(0.5)
    assert page.page.inner_text("#tt-time") == "t = 0.50 s of 1.00 s"
    assert page.page.locator("#tt-drop").count() == 0
    assert page.page.inner_text("#tt-legend").splitlines()[0] == "box (planned pose)"


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
    result = simulate_reference(reference, config, controlled=False, html_path=path)
    assert result.dropped
    return path, side, result.drop_time_s


def test_polygon_playback_draws_the_polygon(browser, triangle_html):
    """The triangle's prism is drawn as a triangle: its area in pixels, centred, apex up (more of
    it below its centroid than above: 5/9), and the page calls it the object."""
    path, side, drop = triangle_html
    page = Page(browser, path)
    mask = box_pixels(page.frame_at(0.0))
    assert page.requests == [path.resolve().as_uri()] and page.errors == []
    pixels_per_m = VIEWPORT["height"] / (2 * VIEW_HALF_WIDTH)
    area = np.sqrt(3) / 4 * side**2 * pixels_per_m**2
    assert mask.sum() == pytest.approx(area, rel=0.12)  # fingertips cover a little of it
    rows, cols = np.nonzero(mask)
    assert abs(cols.mean() - VIEWPORT["width"] / 2) < 10
    centroid_row = VIEWPORT["height"] / 2
    assert np.sum(rows > centroid_row) / len(rows) == pytest.approx(5 / 9, abs=0.05)
    assert page.page.inner_text("#tt-legend").splitlines()[:2] == ["object", "planned object pose (outline)"]
    page.frame_at(0.25)
    assert page.page.inner_text("#tt-drop-note") == f"object dropped at {drop:.2f} s"
