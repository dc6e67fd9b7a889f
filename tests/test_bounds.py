"""Finite ranges, the convexity check on many vertices, and how a run's outcome is classified:
a diverged simulation is not a drop, and "held" means ended within tolerance (issue items 6, 9, 12)."""

import dataclasses
import functools
import math
import typing

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from trajectotree.config import (
    CitoConfig,
    Config,
    ConfigError,
    EstimatorGains,
    GraspGains,
    ImpedanceGains,
    LandingReflexGains,
    ObjectConfig,
    PushReflexGains,
    ReplanConfig,
    SceneConfig,
    SearchConfig,
    SimConfig,
    with_values,
)
from trajectotree.execution import metrics
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.simulate import build_execution_diagram, record_log
from trajectotree.geometry import ConvexPolygon, polygon_problem
from trajectotree.results import RunOutcome, SimLog, outcome_text
from trajectotree.scene.plant import build_scene

SECTIONS = (
    SceneConfig,
    SearchConfig,
    CitoConfig,
    ImpedanceGains,
    GraspGains,
    EstimatorGains,
    PushReflexGains,
    LandingReflexGains,
    SimConfig,
    ReplanConfig,
)
HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)  # a four-finger grasp of the default box


def float_fields(cls) -> list[str]:
    hints = typing.get_type_hints(cls)
    return [f.name for f in dataclasses.fields(cls) if hints[f.name] in (float, float | None)]


@pytest.mark.parametrize("cls", SECTIONS, ids=lambda c: c.__name__)
def test_every_number_has_a_finite_upper_bound(cls):
    """Each float field refuses 1e308 and names itself and a finite range."""
    names = float_fields(cls)
    assert names
    for name in names:
        with pytest.raises(ConfigError) as info:
            cls(**{name: 1e308})
        assert info.value.field.endswith(name) or name in str(info.value), (name, str(info.value))
        assert "inf" not in (info.value.valid or ""), (name, str(info.value))


@pytest.mark.parametrize(
    "section, field, high",
    [
        ("scene", "box_mass", 10.0),
        ("scene", "gravity", 100.0),
        ("scene", "box_depth", 0.3),
        ("controller", "grasp.tip_kp", 2000.0),
        ("controller", "grasp.tip_kd", 5.0),
        ("controller", "grasp.object_kp", 3e4),
        ("controller", "grasp.object_kd", 500.0),
        ("controller", "impedance.kp", 5000.0),
        ("controller", "impedance.kv", 8.0),
        ("controller", "landing_reflex.tip_kp", 2000.0),
        ("controller", "landing_reflex.tip_kd", 5.0),
    ],
)
def test_the_bounds_are_inclusive_and_the_next_value_is_refused(section, field, high):
    path = f"{section}.{field}"
    assert functools.reduce(getattr, path.split("."), with_values(Config(), {path: high})) == high
    with pytest.raises(ConfigError, match=rf"{path} = .* is out of range; valid range: .*{high:g}\]"):
        with_values(Config(), {path: high * (1 + 1e-9)})


def test_the_mass_has_a_lower_end_drake_can_simulate():
    assert SceneConfig(box_mass=0.001).box_mass == 0.001
    with pytest.raises(ConfigError, match=r"scene.box_mass = 1e-300 is out of range; valid range: \[0.001, 10\]"):
        SceneConfig(box_mass=1e-300)


def test_a_disc_of_the_largest_radius_is_accepted_and_a_larger_one_refused():
    """The polygonized disc's vertices and its re-centring round to ~1e-16 m beyond 0.3 m."""
    disc = SceneConfig(object=ObjectConfig(circle_radius=0.3))
    assert disc.shape.circumradius == pytest.approx(0.3, abs=1e-12)
    with pytest.raises(ConfigError, match="circle_radius"):
        SceneConfig(object=ObjectConfig(circle_radius=0.3000001))
    with pytest.raises(ConfigError, match="a vertex is 0.3 m from the centroid; valid range: at most 0.3 m"):
        SceneConfig(object=ObjectConfig(vertices=((0.3000001, 0.0), (-0.15, 0.2), (-0.15, -0.2))))


def circle(n: int, radius: float = 0.1) -> np.ndarray:
    angles = 2 * np.pi * np.arange(n) / n
    return np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)


def test_the_convexity_check_is_right_on_3000_vertices():
    points = circle(3000)
    assert polygon_problem(points) is None and polygon_problem(points[::-1]) is None
    dented = points.copy()
    dented[1234] *= 0.99  # one vertex pushed inwards
    assert polygon_problem(dented) == (
        f"the polygon is not convex (it turns the other way at vertex 1234, ({dented[1234][0]:g}, {dented[1234][1]:g}))"
    )
    twice = circle(1500)[np.r_[0:1500:2, 1:1500:2]]  # every other vertex, twice round
    assert polygon_problem(twice).startswith("the polygon is self-intersecting (its edges turn by 720 deg in all")
    repeated = np.insert(points, 7, points[7], axis=0)
    assert polygon_problem(repeated) == f"vertices 7 and 8 repeat the point ({points[7][0]:g}, {points[7][1]:g})"
    bow_tie = [[0, 0], [0.1, 0.1], [0.1, 0], [0, 0.1]]
    assert "self-intersecting" in polygon_problem(bow_tie)


def test_a_3000_vertex_polygon_is_accepted_with_its_message_one_short_line():
    points = circle(3000)
    config = SceneConfig(object=ObjectConfig(vertices=tuple(map(tuple, points.tolist()))))
    assert len(config.shape.vertices) == 3000
    dented = points.copy()
    dented[5] *= 0.99
    with pytest.raises(ConfigError) as info:
        ObjectConfig(vertices=tuple(map(tuple, dented.tolist())))
    assert str(info.value).startswith("scene.object.vertices = [3000 vertices: [0.1, 0.0], ..., [")
    assert len(str(info.value)) < 300 and "turns the other way at vertex 5" in str(info.value)


@pytest.mark.parametrize("n", [3, 4, 7, 64, 3000])
def test_back_offsets_are_the_polygons_extent_behind_each_face(n):
    polygon = ConvexPolygon.from_points(circle(n) * [1.0, 0.6] + [0.01, 0.0])
    brute = np.min(polygon.vertices @ polygon.normals.T, axis=0)  # O(V^2)
    np.testing.assert_allclose(polygon.back_offsets, brute, rtol=0, atol=1e-15)
    box = ConvexPolygon.box(0.2, 0.1)
    np.testing.assert_array_equal(box.back_offsets, -box.offsets[[2, 3, 0, 1]])


def synthetic_log(t, x, step_error=None) -> SimLog:
    """A run's log of object poses x (T, 3) at times t, the plan holding the start pose."""
    T = len(t)
    return SimLog(
        t=np.asarray(t, dtype=float),
        x=np.asarray(x, dtype=float),
        q=np.zeros((T, 8)),
        x_plan=np.zeros((T, 3)),
        f_W=np.zeros((T, 4, 2)),
        f_W_plan=np.zeros((T, 4, 2)),
        sim_time_s=0.1,
        controller="grasp",
        conditions={},
        step_error=step_error,
    )


def test_a_free_fall_is_a_drop_and_a_faster_motion_a_divergence():
    t = np.arange(0.0, 10.0, 0.01)
    fall = np.zeros((len(t), 3))
    fall[:, 1] = -0.5 * 9.81 * t**2  # no floor: 490 m in 10 s, at 98 m/s at the end
    dropped = metrics.evaluate(synthetic_log(t, fall), 0.05, 9.81)
    assert dropped.outcome is RunOutcome.DROPPED and dropped.divergence is None and dropped.dropped
    flung = fall.copy()
    flung[500:, 0] = 3.0  # 3 m in 10 ms at 5 s, falling at 49 m/s: 304 m/s, beyond 100 + 49 m/s
    diverged = metrics.evaluate(synthetic_log(t, flung), 0.05, 9.81)
    assert diverged.outcome is RunOutcome.DIVERGED and diverged.diverged_at_s == pytest.approx(5.0)
    assert diverged.divergence.startswith("the object moved at 304 m/s at 5.00 s, faster than gravity")
    assert diverged.dropped and diverged.drop_time_s < 5.0  # it fell before (the drop rule sees those samples)
    pushed = metrics.evaluate(synthetic_log(t, flung), 0.05, 9.81, push_speed=400.0)
    assert pushed.outcome is RunOutcome.DROPPED  # a 400 m/s push could have done it


def test_a_state_that_is_not_finite_is_a_divergence_not_a_drop():
    t = np.arange(0.0, 1.0, 0.01)
    x = np.zeros((len(t), 3))
    x[40:] = np.nan
    result = metrics.evaluate(synthetic_log(t, x), 0.05, 9.81)
    assert result.outcome is RunOutcome.DIVERGED and not result.dropped
    assert result.divergence == "the state is not finite at 0.40 s" and result.diverged_at_s == pytest.approx(0.4)
    assert np.isfinite(result.abs_error).all() and result.final_error == (0.0, 0.0, 0.0)
    summary = result.to_json()
    assert summary["outcome"] == "diverged" and summary["within_tolerance"] is False
    assert outcome_text(summary) == "the simulation DIVERGED at 0.40 s: the state is not finite at 0.40 s"


def test_drake_refusing_a_step_is_recorded_as_a_divergence():
    """A real run whose box starts at 1e300 m/s: Drake's contact solver throws on its first step,
    and the run is a result with that reason, not a traceback."""
    scene, config = build_scene(), Config()
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=0.3)
    execution = build_execution_diagram(reference, config)
    context = execution.initial_context(reference)
    plant_context = execution.plant.GetMyMutableContextFromRoot(context)
    execution.plant.SetVelocities(plant_context, execution.box, np.array([0.0, 1e300, 0.0]))
    log = record_log(execution, Simulator(execution.diagram, context), {})
    assert log.step_error
    result = metrics.evaluate(log, config.sim.drop_distance, config.scene.gravity)
    assert result.outcome is RunOutcome.DIVERGED and result.divergence.startswith("Drake refused a step after 0.00 s")


def test_held_means_not_dropped_and_ended_within_tolerance():
    t = np.arange(0.0, 2.0, 0.01)
    x = np.zeros((len(t), 3))
    x[:, 2] = np.linspace(0.0, 1.10, len(t))  # turns away from the plan, slowly: 1.10 rad (63 deg) at the end
    short = metrics.evaluate(synthetic_log(t, x), 0.05, 9.81)
    assert short.outcome is RunOutcome.OFF_PLAN and not short.dropped and not short.within_tolerance
    summary = short.to_json()
    assert summary["within_tolerance"] is False and summary["outcome"] == "off_plan" and summary["dropped"] is False
    assert outcome_text(summary, "box") == (
        "box not dropped, but ended 1.100 rad (63 deg) and 0.0 mm off the plan's final pose (tolerance: 3 deg and 5 mm)"
    )
    x[:, 2] = math.radians(2.9)
    x[:, 0] = 0.004
    held = metrics.evaluate(synthetic_log(t, x), 0.05, 9.81)
    assert held.outcome is RunOutcome.HELD and held.to_json()["within_tolerance"] is True
    assert outcome_text(held.to_json(), "box") == "box held (ended within 3 deg and 5 mm of the plan's final pose)"
    x[:, 0] = 0.006  # 6 mm off: outside the position tolerance
    assert metrics.evaluate(synthetic_log(t, x), 0.05, 9.81).outcome is RunOutcome.OFF_PLAN
