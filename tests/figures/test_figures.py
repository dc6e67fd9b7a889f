"""The single-run figures (trajectotree.figures.run) checked against closed-form geometry and
the data they were given: where a box, a finger, a contact or a cone is drawn, which
force each line shows, what the forces figure's scale and legend hold."""

import dataclasses
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from trajectotree.cli import main  # noqa: E402
from trajectotree.contact_plan import ContactNode, ContactPlan  # noqa: E402
from trajectotree.execution.metrics import evaluate  # noqa: E402
from trajectotree.figures.run import (  # noqa: E402
    ARROW_MAX_LENGTH,
    FINGER_COLORS,
    arrow_newtons_per_cm,
    arrow_scale_text,
    contact_node_legend_handles,
    figure_finger_forces,
    figure_keyframes,
    figure_model,
    force_arrow,
    forces_title,
    plot_box,
    plot_contact_node,
    plot_contacts,
    plot_finger_force,
    plot_force_arrows,
    plot_friction_cones,
    plot_hand,
    plot_segments,
    save_figure,
    segment_spans,
)
from trajectotree.results import SimLog  # noqa: E402
from trajectotree.scene.plant import NUM_FINGERS, build_scene  # noqa: E402


def span_x(patch) -> tuple[float, ...]:
    """The distinct x data coordinates of a patch's outline (axvspan: its start and end)."""
    return tuple(np.unique(np.round(patch.get_patch_transform().transform(patch.get_path().vertices)[:, 0], 12)))


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def test_box_corners_are_the_rotated_half_extents(ax):
    x, y, theta, w, h = 0.03, -0.02, math.pi / 6, 0.2, 0.1
    (patch,) = plot_box(ax, w, h, (x, y, theta))
    c, s = math.cos(theta), math.sin(theta)
    corners = [
        (x + c * u - s * v, y + s * u + c * v) for u, v in ((0.1, -0.05), (0.1, 0.05), (-0.1, 0.05), (-0.1, -0.05))
    ]
    np.testing.assert_allclose(patch.get_xy()[:4], corners, atol=1e-15)
    np.testing.assert_allclose(patch.get_xy()[4], corners[0], atol=1e-15)  # closed outline


def test_hand_is_drawn_where_the_plant_puts_joints_and_fingertips(scene, ax):
    q = np.array([0.3, 1.1, -0.2, 0.9, 0.5, 0.4, 0.1, 1.4])
    artists = plot_hand(ax, scene, q)
    tips = [a for a in artists if isinstance(a, matplotlib.patches.Circle)]
    plant = scene.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, scene.positions(scene.config.initial_pose, q))
    p_WF = scene.fingertip_positions(q)
    assert len(tips) == NUM_FINGERS
    for i, tip in enumerate(tips):
        np.testing.assert_allclose(tip.center, p_WF[i], atol=1e-12)
        assert tip.radius == pytest.approx(scene.tip_radius)
        assert matplotlib.colors.same_color(tip.get_facecolor(), FINGER_COLORS[i])
    links = [a for a in artists if isinstance(a, matplotlib.lines.Line2D) and a.get_linestyle() == "-"]
    for i, line in enumerate(links):  # base, elbow (joint 2), fingertip centre
        joints = [plant.GetJointByName(f"finger{i}_joint{j}", scene.hand).frame_on_child() for j in (1, 2)]
        expected = [frame.CalcPoseInWorld(context).translation()[:2] for frame in joints] + [p_WF[i]]
        np.testing.assert_allclose(np.column_stack(line.get_data()), expected, atol=1e-12)


def test_model_figure_draws_each_fingers_full_reach_around_its_base(scene):
    fig = figure_model(scene)
    ax = fig.axes[0]
    reach = [p for p in ax.patches if isinstance(p, matplotlib.patches.Circle) and not p.get_fill()]
    stretched = scene.fingertip_positions(np.zeros(8))  # q = 0: both links in line, the farthest reach
    assert len(reach) == NUM_FINGERS
    for circle, finger, tip in zip(reach, scene.fingers, stretched):
        np.testing.assert_allclose(circle.center, finger.p_W_base)
        assert circle.radius == pytest.approx(np.linalg.norm(tip - finger.p_W_base), abs=1e-12)
    c = scene.config
    box = [p for p in ax.patches if isinstance(p, matplotlib.patches.Polygon)][0]
    np.testing.assert_allclose(box.get_xy()[:4].mean(axis=0), c.initial_pose[:2], atol=1e-15)
    assert [t.get_text() for t in ax.texts if t.get_text().startswith("finger")] == [f"finger {i}" for i in range(4)]
    plt.close(fig)


def test_contacts_normals_and_cones_in_the_world(ax):
    pose = (0.01, 0.02, math.pi / 2)  # the box's +x face points along +y in W
    p_BC, n_B = np.array([[0.1, 0.0], [-0.1, 0.02]]), np.array([[1.0, 0.0], [-1.0, 0.0]])
    scatter, arrows = plot_contacts(ax, pose, p_BC, n_B)
    np.testing.assert_allclose(scatter.get_offsets(), [[0.01, 0.12], [-0.01, -0.08]], atol=1e-15)
    np.testing.assert_allclose(np.column_stack([arrows.U, arrows.V]), [[0.0, 1.0], [0.0, -1.0]], atol=1e-15)
    mu, length = 0.5, 0.03
    wedge = plot_friction_cones(ax, pose, p_BC[:1], n_B[:1], mu, length=length)[0].get_xy()
    r = length / math.hypot(1.0, mu)  # edge directions -n -+ mu t, t = z x n, unit length
    np.testing.assert_allclose(
        wedge[:3], [[0.01, 0.12], [0.01 + mu * r, 0.12 - r], [0.01 - mu * r, 0.12 - r]], atol=1e-15
    )


def test_finger_force_lines_are_the_magnitudes_and_the_drop_is_shaded(ax):
    t = np.linspace(0.0, 1.0, 5)
    f_sim = np.column_stack([3.0 * t, 4.0 * t])
    f_plan = np.column_stack([np.ones(5), np.zeros(5)])
    sim, plan, shade = plot_finger_force(ax, t, f_sim, f_plan, color="tab:red", drop_time=0.5)
    np.testing.assert_allclose(sim.get_ydata(), 5.0 * t)
    np.testing.assert_allclose(plan.get_ydata(), np.ones(5))
    assert sim.get_linestyle() == "-" and plan.get_linestyle() == "--"
    assert matplotlib.colors.same_color(plan.get_color(), "tab:red")
    assert span_x(shade) == pytest.approx((0.5, 1.0))
    assert len(plot_finger_force(ax, t, f_sim, f_plan)) == 2  # no drop: nothing shaded


def test_segments_mark_boundaries_and_shade_the_fingers_switches(ax):
    spans = segment_spans([None, 0, None, 0], knots_per_segment=3, dt=0.1)
    assert [finger for _, _, finger in spans] == [0, None, 0]
    np.testing.assert_allclose([(t0, t1) for t0, t1, _ in spans], [(0.0, 0.3), (0.3, 0.6), (0.6, 0.9)])
    artists = plot_segments(ax, spans, 0)
    boundaries = [a.get_xdata()[0] for a in artists if isinstance(a, matplotlib.lines.Line2D)]
    assert boundaries == pytest.approx([0.3, 0.6])
    shaded = [span_x(a) for a in artists if not isinstance(a, matplotlib.lines.Line2D)]
    assert shaded == [pytest.approx((0.0, 0.3)), pytest.approx((0.6, 0.9))]
    assert len(plot_segments(ax, spans, 1)) == 2  # finger 1 never switches


def synthetic_run() -> SimLog:
    """A box that follows the plan, then falls (0.1 m off from t = 0.6 s) while a finger squeezes 50 N."""
    t = np.linspace(0.0, 1.0, 11)
    x_plan = np.zeros((11, 3))
    x = x_plan.copy()
    x[6:, 1] = -0.1
    f_plan = np.zeros((11, 4, 2))
    f_plan[:, :, 0] = [1.0, -1.0, 2.0, -2.0]
    f_W = f_plan.copy()
    f_W[:, 1, 1] = 0.5
    f_W[8:, 3, 0] = -50.0
    return SimLog(
        t=t,
        x=x,
        q=np.zeros((11, 8)),
        x_plan=x_plan,
        f_W=f_W,
        f_W_plan=f_plan,
        sim_time_s=0.1,
        controller="grasp",
        conditions={},
    )


def test_forces_figure_shares_one_scale_set_before_the_drop_and_marks_segments():
    result = evaluate(synthetic_run(), drop_distance=0.05, gravity=9.81)
    assert result.dropped and result.drop_time_s == pytest.approx(0.6)
    spans = segment_spans([None, 0, 2], knots_per_segment=2, dt=0.1)
    assert spans == [(0.0, 0.2, 0), (0.2, 0.4, 2)]
    fig = figure_finger_forces(result, spans)
    axes = fig.axes
    assert len(axes) == NUM_FINGERS and len({ax.get_ylim() for ax in axes}) == 1
    assert axes[0].get_ylim() == pytest.approx((-0.03 * 2.0, 1.1 * 2.0))  # |f| <= 2 N up to the drop; 50 N clipped
    for i, ax in enumerate(axes):
        simulated, planned = ax.lines[:2]
        np.testing.assert_allclose(simulated.get_ydata(), np.linalg.norm(result.f_W[:, i], axis=1))
        np.testing.assert_allclose(planned.get_ydata(), np.linalg.norm(result.f_W_plan[:, i], axis=1))
        shaded = [p for p in ax.patches if p.get_label() == "segment in which this finger switches"]
        assert len(shaded) == {0: 1, 2: 1}.get(i, 0)  # finger 0 switches in segment 1, finger 2 in segment 2
    assert all("|f| [N]" in ax.get_ylabel() for ax in axes) and "|f|" in fig._suptitle.get_text()
    assert fig._suptitle.get_text().splitlines()[1] == "grasp controller"  # no goal given
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == [
        "simulated |f|",
        "planned |f|",
        "after the drop (may be clipped)",
        "segment in which this finger switches",
        "segment boundary",
    ]
    plt.close(fig)


def node(theta: float, switching: int | None) -> ContactNode:
    p_BC = np.array([[0.1, 0.0], [0.0, 0.05], [-0.1, 0.0], [0.0, -0.05]])
    n_B = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    return ContactNode(
        object_pose=np.array([0.0, 0.0, theta]),
        q=np.tile([0.25, 1.2], 4),
        arclengths=np.zeros(4),
        p_BC=p_BC,
        n_B=n_B,
        switching_finger=switching,
        closure_margin=0.1,
    )


def test_keyframes_one_panel_per_node_with_the_switching_finger(scene, tmp_path):
    nodes = (node(0.0, None), node(0.1, 2), node(0.2, None))
    fig = figure_keyframes(scene, ContactPlan(goal=0.2, success=True, nodes=nodes))
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == [
        "n=0  θ = +0.00 rad (+0.0°)\ninitial grasp",
        "n=1  θ = +0.10 rad (+5.7°)\nfinger 2 moves",
        "n=2  θ = +0.20 rad (+11.5°)\nno switch",
    ]
    thick = [line for line in fig.axes[1].lines if line.get_linewidth() == 4.0]
    assert len(thick) == 1 and matplotlib.colors.same_color(thick[0].get_color(), "k")
    assert "goal θ = +0.200 rad (+11.5°)" in fig._suptitle.get_text()
    out = save_figure(fig, tmp_path / "keyframes.svg", dpi=110)  # the format the suffix names
    plt.close(fig)
    svg = (tmp_path / "keyframes.svg").read_text()
    assert out.endswith("keyframes.svg") and svg.startswith("<?xml") and "friction cone" in svg


def test_keyframes_draw_the_cones_the_plan_was_searched_with(scene):
    nodes = (node(0.0, None), node(0.1, 2))
    for mu_plan, shown in ((0.49, "mu = 0.49"), (float("nan"), f"mu = {scene.config.mu:.2g}")):
        fig = figure_keyframes(scene, ContactPlan(goal=0.1, success=True, nodes=nodes, mu_plan=mu_plan))
        assert any(shown in t.get_text() for t in fig.legends[0].get_texts())
        plt.close(fig)


def test_contact_node_numbers_the_fingers_and_marks_the_previous_contact(scene, ax):
    previous, current = node(0.0, None), node(0.1, 1)
    plot_contact_node(ax, scene, current, mu=0.7, previous=previous)
    assert sorted(t.get_text() for t in ax.texts) == ["0", "1", "2", "3"]
    hollow = [line for line in ax.lines if line.get_marker() == "o" and line.get_markerfacecolor() == "none"]
    c, s = math.cos(0.1), math.sin(0.1)
    np.testing.assert_allclose(np.column_stack(hollow[0].get_data())[0], [c * 0.0 - s * 0.05, s * 0.0 + c * 0.05])
    labels = [h.get_label() for h in contact_node_legend_handles(0.7)]
    assert labels == [
        "contact (finger's colour; arrow: normal)",
        "friction cone (mu = 0.7)",
        "switching finger's previous contact",
        "switching finger",
        "holding fingers (numbered at their bases)",
    ]


def test_search_command_draws_the_keyframes_in_the_format_its_suffix_names(tmp_path):
    out = tmp_path / "keyframes.svg"
    assert main(["search", "--goal", "0.3", "--segments", "2", "--figure", str(out)]) == 0
    svg = out.read_text()
    assert svg.startswith("<?xml") and "switching finger" in svg and "friction cone" in svg


# ---- a convex polygon instead of the box ------------------------------------------

QUAD = ((-0.09, -0.05), (0.08, -0.06), (0.06, 0.06), (-0.05, 0.04))


def test_polygon_outline_is_its_vertices_at_the_pose(ax):
    from trajectotree.figures.run import plot_object
    from trajectotree.geometry import ConvexPolygon

    shape = ConvexPolygon.from_points(QUAD)
    pose = (0.02, -0.01, 2.0)
    (patch,) = plot_object(ax, shape, pose)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    expected = [(pose[0] + c * u - s * v, pose[1] + s * u + c * v) for u, v in shape.vertices]
    np.testing.assert_allclose(patch.get_xy()[:4], expected, atol=1e-15)
    np.testing.assert_allclose(patch.get_xy()[4], expected[0], atol=1e-15)


def test_model_figure_of_a_polygon_draws_it_the_hand_and_each_fingers_reachable_contacts():
    from trajectotree.config import ObjectConfig, SceneConfig

    config = SceneConfig(object=ObjectConfig(vertices=QUAD), initial_pose=(0.01, 0.02, 0.3))
    scene = build_scene(config)
    reachable = [np.array([0.02, 0.06]), np.array([]), np.array([0.3]), np.array([0.1, 0.12, 0.5])]
    q = np.array([0.3, 1.1, -0.2, 0.9, 0.5, 0.4, 0.1, 1.4])
    fig = figure_model(scene, q=q, reachable=reachable, note="a note")
    ax = fig.axes[0]
    outline = [p for p in ax.patches if isinstance(p, matplotlib.patches.Polygon)][0]
    from trajectotree.geometry import box_to_world

    corners = [box_to_world(config.initial_pose, v) for v in config.shape.vertices]
    np.testing.assert_allclose(outline.get_xy()[:4], corners, atol=1e-15)
    dots = ax.collections
    assert len(dots) == 3  # finger 1 reaches nothing: no dots
    for dot, i in zip(dots, (0, 2, 3)):
        p_B, n_B = config.shape.points(reachable[i])
        expected = [box_to_world(config.initial_pose, p) for p in p_B + 0.004 * (i + 1) * n_B]
        np.testing.assert_allclose(dot.get_offsets(), expected, atol=1e-15)
        assert matplotlib.colors.same_color(dot.get_facecolor()[0], FINGER_COLORS[i])
    tips = [p for p in ax.patches if isinstance(p, matplotlib.patches.Circle) and p.get_fill()]
    np.testing.assert_allclose([t.center for t in tips], scene.fingertip_positions(q), atol=1e-12)
    assert ax.get_title() == "Planar four-finger hand and quadrilateral (146 cm^2)\na note"
    plt.close(fig)


# ---- scales, units and titles of the pictures -------------------------------------------------


def test_keyframes_share_metre_axes_labelled_on_the_outer_panels(scene):
    """Seven nodes in rows of five: every panel on the same axes in m, the x label under the last
    panel of each column (the second row's two, the first row's three with nothing below), the
    y label on the left column, and ticks that read as a scale."""
    nodes = tuple(node(0.05 * n, None if n == 0 else n % 4) for n in range(7))
    fig = figure_keyframes(scene, ContactPlan(goal=0.3, success=True, nodes=nodes))
    panels = [ax for ax in fig.axes if ax.axison]
    assert len(panels) == 7 and len(fig.axes) == 10  # three empty slots, drawn as nothing
    assert [ax.get_xlabel() for ax in panels] == ["", "", "x [m]", "x [m]", "x [m]", "x [m]", "x [m]"]
    assert [ax.get_ylabel() for ax in panels] == ["y [m]", "", "", "", "", "y [m]", ""]
    for ax in panels:
        assert ax.get_xlim() == pytest.approx((-0.26, 0.26)) and ax.get_ylim() == pytest.approx((-0.26, 0.26))
        assert list(ax.get_xticks()) == pytest.approx([-0.2, -0.1, 0.0, 0.1, 0.2])
    fig.canvas.draw()
    shown = [t.get_text() for t in panels[5].get_xticklabels() if t.get_visible()]
    assert shown == ["−0.2", "−0.1", "0.0", "0.1", "0.2"]
    plt.close(fig)


def test_forces_title_names_the_goal_the_controller_and_a_changed_world():
    run = evaluate(synthetic_run(), drop_distance=0.05, gravity=9.81)
    assert forces_title(run, 1.5708).splitlines() == [
        "force of each finger on the box, magnitude |f|",
        "goal θ = +1.571 rad (+90.0°), grasp controller",
    ]
    changed = dataclasses.replace(
        run,
        controller="paper",
        conditions={
            "sim_mu": 0.55,
            "plan_mu": 0.7,
            "sim_mass": 0.06,
            "plan_mass": 0.05,
            "push": {"force": [0.2, 0.0], "time_s": 5.5, "duration_s": 0.2},
        },
    )
    assert forces_title(changed, -0.3).splitlines()[1] == (
        "goal θ = -0.300 rad (-17.2°), paper's controller (eq. 20); simulated mu 0.55 (plan 0.7), "
        "mass 60 g (plan 50 g), push (0.2, 0) N at 5.5 s for 0.2 s"
    )
    uncontrolled = dataclasses.replace(run, controller="none")
    assert forces_title(uncontrolled, "0.3").splitlines()[1] == "no controller (zero torque)"  # not a number: left out
    fig = figure_finger_forces(run, goal=0.5)
    assert fig._suptitle.get_text() == forces_title(run, 0.5)
    plt.close(fig)


@pytest.mark.parametrize(
    ("top", "scale"), [(0.0, 1.0), (0.9, 0.2), (1.0, 0.2), (1.01, 0.5), (5.0, 1.0), (5.2, 2.0), (40.0, 10.0)]
)
def test_arrow_scale_is_the_round_value_that_draws_the_largest_force_at_most_5_cm(top, scale):
    forces = np.zeros((3, 4, 2))
    forces[1, 2] = (0.6 * top, -0.8 * top)
    assert arrow_newtons_per_cm(forces) == pytest.approx(scale)
    assert arrow_scale_text(scale) == f"1 cm = {scale:g} N, capped at 12 cm"


def test_force_arrow_starts_on_the_fingertip_and_is_as_long_as_the_scale_says():
    tip, r = np.array([0.1, -0.05]), 0.01
    start, end = force_arrow(tip, (0.0, 0.6), r, newtons_per_cm=0.2)  # 0.6 N up: 3 cm
    np.testing.assert_allclose(start, [0.1, -0.04])
    np.testing.assert_allclose(end, [0.1, -0.01])
    start, end = force_arrow(tip, (-30.0, 0.0), r, newtons_per_cm=0.2)  # 150 cm: capped
    np.testing.assert_allclose(start, [0.09, -0.05])
    np.testing.assert_allclose(end, [0.09 - ARROW_MAX_LENGTH, -0.05])
    assert force_arrow(tip, (0.01, 0.0), r, newtons_per_cm=0.2) is None  # a finger off the box


def test_force_arrows_are_drawn_in_the_fingers_colours_where_they_push(ax):
    tips = np.array([[0.1, 0.0], [0.0, 0.05], [-0.1, 0.0], [0.0, -0.05]])
    forces = np.array([[-1.0, 0.0], [0.0, 0.0], [0.5, 0.0], [0.0, 0.4]])  # finger 1 pushes nothing
    arrows = plot_force_arrows(ax, tips, forces, 0.01, newtons_per_cm=0.5)
    assert len(arrows) == 3
    for arrow, i in zip(arrows, (0, 2, 3)):
        assert matplotlib.colors.same_color(arrow.get_facecolor(), FINGER_COLORS[i])
        xy = arrow.get_xy()
        start, end = force_arrow(tips[i], forces[i], 0.01, 0.5)
        direction = (end - start) / np.linalg.norm(end - start)
        along = (xy - start) @ direction  # the outline spans start..end along the force
        assert along.min() == pytest.approx(0.0, abs=1e-9) and along.max() == pytest.approx(np.linalg.norm(end - start))


def test_run_frame_has_labelled_metre_axes_the_time_numbers_and_force_arrows(scene, ax):
    """A GIF frame (plot_run_frame): x, y in m over the view, the title as given (the time), the
    fingers' numbers at their bases, the planned pose dashed and one arrow per pushing finger."""
    from trajectotree.figures.run import plot_run_frame

    q = np.tile([0.25, 1.2], 4)
    forces = np.array([[0.0, 0.5], [0.0, 0.0], [0.3, 0.0], [0.0, -0.2]])
    plot_run_frame(
        ax,
        scene,
        (0.0, 0.0, 0.1),
        q,
        half_width=0.32,
        planned_pose=(0.0, 0.01, 0.0),
        forces=forces,
        newtons_per_cm=0.2,
        title="t = 1.50 s of 3.00 s",
    )
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_title()) == ("x [m]", "y [m]", "t = 1.50 s of 3.00 s")
    assert ax.get_xlim() == pytest.approx((-0.32, 0.32)) and ax.get_ylim() == pytest.approx((-0.32, 0.32))
    assert [t.get_text() for t in ax.texts] == ["0", "1", "2", "3"]
    dashed = [p for p in ax.patches if isinstance(p, matplotlib.patches.Polygon) and p.get_linestyle() == "--"]
    assert len(dashed) == 1
    arrows = [p for p in ax.patches if isinstance(p, matplotlib.patches.FancyArrow)]
    assert [a.get_facecolor() for a in arrows] == [matplotlib.colors.to_rgba(FINGER_COLORS[i]) for i in (0, 2, 3)]
    tips = scene.fingertip_positions(q)
    for arrow, i in zip(arrows, (0, 2, 3)):
        start, end = force_arrow(tips[i], forces[i], scene.tip_radius, 0.2)
        assert np.min(np.linalg.norm(arrow.get_xy() - end, axis=1)) == pytest.approx(0.0, abs=1e-12)  # its tip
