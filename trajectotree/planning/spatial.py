"""Planning for a hand in space: the contact search in space (search.space_tree, find_space_contact_plan), then the
keyframes formulation in space (cito.spatial: one IPOPT program per segment, the segments independent, their
ends the search's nodes: solved at once in the segment pool of segment_pool.py), the segments joined at their
nodes into one trajectory, checked from its arrays alone (planning.physics.check_space_physics) and written as
plan.npz (results.SPACE_TRAJECTORY_ARRAYS) and plan.json (the object, the integration rule, the check,
the solve report per segment and the contact sequence). With cito.formulation joint (`plan --formulation joint`)
the segments are one program instead (cito.space_joint.solve_space_joint: the nodes free but the start and the goal),
reported as one solve.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trajectotree.cito.space_cito import cito_cold_start, cito_warm_start, solve_space_cito
from trajectotree.cito.space_hand import SpaceHandModel, hand_model
from trajectotree.cito.space_joint import solve_space_joint
from trajectotree.cito.spatial import SegmentSpec, SpaceSegmentResult, segment_spec, solve_space_segment
from trajectotree.config import CitoConfig, Config, config_to_dict, mu_plan
from trajectotree.contact_plan import SpaceContactPlan
from trajectotree.geometry import quaternion_angle
from trajectotree.planning.physics import SpaceObjectModel, check_space_physics
from trajectotree.planning.segment_pool import run_on_pool
from trajectotree.planning.start import space_start_root
from trajectotree.results import SPACE_INTEGRATION, SpacePhysicsCheck, SpaceTrajectory
from trajectotree.search.space_tree import find_space_contact_plan, space_initial_grasp
from trajectotree.start import SpaceStartState

GOAL_TOLERANCE = np.radians(2.0)  # rad, how close to its goal orientation a plan in space ends to count


@dataclass(frozen=True)
class SpacePlanResult:
    """A plan in space: the search's contact sequence, the segments' solves and the trajectory, checked."""

    goal: tuple[float, float, float, float]  # unit quaternion [w, x, y, z]
    success: bool  # searched, every segment solved, the check passed, within GOAL_TOLERANCE of the goal
    status: str
    contact_plan: SpaceContactPlan
    trajectory: SpaceTrajectory | None
    physics_check: SpacePhysicsCheck | None
    object_model: SpaceObjectModel
    mu_plan: float
    final_error_rad: float  # the angle from the last knot's orientation to the goal (nan: nothing solved)
    segments: tuple[dict, ...]  # per segment: success, status, build and solve times
    search_time_s: float
    solve_time_s: float  # s of wall time, the segments' programs (at once on the segment pool)
    total_time_s: float
    method: str = "trajectotree"  # or general CITO's "cito" and "cito-warm" (plan_space_cito)
    formulation: str = "keyframes"  # TrajectoTree's (cito.formulation): a program per segment, or "joint": one
    start: dict | None = None  # the measured start it planned from (start.SpaceStartState.to_json), if any

    def to_json(self) -> dict:
        return {
            "kind": "space",
            "method": self.method,
            "formulation": self.formulation,
            "goal_quaternion": [float(v) for v in self.goal],
            "success": self.success,
            "status": self.status,
            "object": {**self.object_model.to_json(), "mu_plan": self.mu_plan},
            "integration": SPACE_INTEGRATION,
            "final_error_rad": None if not np.isfinite(self.final_error_rad) else float(self.final_error_rad),
            "physics_check": None if self.physics_check is None else self.physics_check.to_json(),
            "segments": list(self.segments),
            "search_time_s": self.search_time_s,
            "solve_time_s": self.solve_time_s,
            "total_time_s": self.total_time_s,
            "contact_plan": self.contact_plan.to_json(),
        } | ({} if self.start is None else {"start": self.start})


def object_model(scene) -> SpaceObjectModel:
    """The object and radii the check needs, from a SpaceScene (a uniform box's inertia about its centre)."""
    return SpaceObjectModel(
        size=tuple(float(s) for s in scene.object.size),
        mass=scene.object.mass,
        inertia=scene.object.inertia,
        gravity=scene.gravity,
        tip_radius=scene.tip_radius,
        link_radii=tuple(c.radius for c in scene.link_capsules()[0]),
    )


@dataclass(frozen=True)
class SpaceSegmentTask:
    """One segment's program (plain values: it pickles to a worker process)."""

    model: SpaceHandModel
    spec: SegmentSpec
    mu: float  # the planning friction mu_plan
    cito: CitoConfig


def solve_space_task(task: SpaceSegmentTask) -> SpaceSegmentResult:
    """A worker's entry point: one segment's program built and solved in this process."""
    return solve_space_segment(task.model, task.model.chains, task.spec, task.mu, task.cito)


def solve_space_segments(tasks: list[SpaceSegmentTask], workers: int | None) -> list[SpaceSegmentResult]:
    """The tasks' results in order: in this process (workers 1 or one task), else on local processes as
    segment_pool.run_on_pool runs them: from the main thread on the pool it keeps (one process per core,
    `workers` None), from another on a pool of `workers` started for these tasks and shut down after."""
    size = (os.cpu_count() or 1) if workers is None else workers
    if min(len(tasks), size) <= 1:
        return [solve_space_task(t) for t in tasks]
    return run_on_pool(solve_space_task, tasks, size)


def plan_space(
    scene, goal_quaternion, config: Config, workers: int | None = None, start: SpaceStartState | None = None
) -> SpacePlanResult:
    """Plans the cube of the hand in space `scene` (scene.spatial.SpaceScene) from its start pose (or the measured
    `start`, checked by planning.start.space_start_root: StartRefused before any planning) to the unit quaternion
    `goal_quaternion`: Algorithm 1 in space, rooted at the start's grasp when given, then the segments' programs,
    at once on `workers` local processes (None: one per core; 1: one after another in this process,
    solve_space_segments). The first knot is the start's state, its joints refined onto the contacts
    (cito.spatial.segment_spec: each fingertip moves at most planning.start.SPACE_TOUCH_DISTANCE)."""
    t0 = time.perf_counter()
    mu = mu_plan(config.scene, config.search)
    goal = tuple(float(v) for v in goal_quaternion)
    root = None if start is None else space_start_root(scene, start, config)
    contact_plan = find_space_contact_plan(scene, goal, config.search, mu, root)
    search_time = time.perf_counter() - t0
    model = object_model(scene)
    common = dict(goal=goal, contact_plan=contact_plan, object_model=model, mu_plan=mu, search_time_s=search_time)
    common["formulation"] = config.cito.formulation
    common["start"] = None if start is None else start.to_json()
    if not contact_plan.success:
        return SpacePlanResult(
            success=False,
            status="search: " + contact_plan.reason,
            trajectory=None,
            physics_check=None,
            final_error_rad=float("nan"),
            segments=(),
            solve_time_s=0.0,
            total_time_s=time.perf_counter() - t0,
            **common,
        )
    t1 = time.perf_counter()
    hand = hand_model(scene)
    nodes = contact_plan.nodes
    specs = [segment_spec(hand, hand.chains, a, b) for a, b in zip(nodes[:-1], nodes[1:])]
    if config.cito.formulation == "joint":
        results = solve_space_joint(hand, hand.chains, specs, mu, config.cito)
    else:
        results = solve_space_segments([SpaceSegmentTask(hand, spec, mu, config.cito) for spec in specs], workers)
    return _checked(scene, results, time.perf_counter() - t1, t0, common)


def _checked(scene, results, solve_time: float, t0: float, common: dict) -> SpacePlanResult:
    """The result of solved programs (SpaceSegmentResult, one per segment or general CITO's one): joined, checked
    from the arrays, within GOAL_TOLERANCE of the goal or failing with the reasons; `t0` when planning began."""
    trajectory = join_segments(scene, results)
    check = check_space_physics(trajectory.arrays(), common["object_model"], common["mu_plan"])
    error = quaternion_angle(trajectory.x[-1, :4], np.asarray(common["goal"]))
    trajectotree = common.get("method", "trajectotree") == "trajectotree"
    joint = trajectotree and common.get("formulation") == "joint"  # one program: its solve reported once
    reports = results[:1] if joint else results
    failed = [i for i, r in enumerate(reports) if not r.success]
    name = "joint program" if joint else "segment {}" if trajectotree else common["method"] + " program"
    reasons = [f"{name.format(i)}: {results[i].status}" for i in failed]
    reasons += [] if check.passed else ["physics check: " + check.reason]
    if error > GOAL_TOLERANCE:
        reasons.append(f"ends {np.degrees(error):.2f} deg from the goal (limit {np.degrees(GOAL_TOLERANCE):g} deg)")
    return SpacePlanResult(
        success=not reasons,
        status="; ".join(reasons) or "Success",
        trajectory=trajectory,
        physics_check=check,
        final_error_rad=error,
        segments=tuple(
            {
                "success": r.success,
                "status": r.status,
                "build_time_s": r.build_time_s,
                "solve_time_s": r.solve_time_s,
                "cpu_time_s": r.cpu_time_s,
                "pid": r.pid,
            }
            for r in reports
        ),
        solve_time_s=solve_time,
        total_time_s=time.perf_counter() - t0,
        **common,
    )


def plan_space_cito(
    scene, goal_quaternion, config: Config, method: str, workers: int | None = None, warm: SpacePlanResult | None = None
) -> SpacePlanResult:
    """General CITO in space (cito.space_cito.SpaceCitoRows: one program over the whole horizon, no contact plan), the
    plane's baselines in space: "cito" from the search's best initial grasp held along the straight slerp
    (search.space_tree.space_initial_grasp: no tree search, its time counted as the search's), "cito-warm" from
    TrajectoTree's plan's trajectory (`warm`, else planned here by plan_space on `workers`: its whole time is
    the search's). A program IPOPT does not solve, or whose plan fails the physics check or ends off the goal,
    is a result with the reason; the result's contact_plan is the initial grasp's or the warm start's."""
    t0 = time.perf_counter()
    mu = mu_plan(config.scene, config.search)
    goal = tuple(float(v) for v in goal_quaternion)
    if method == "cito":
        contact_plan = space_initial_grasp(scene, goal, config.search, mu)
    else:
        warm = plan_space(scene, goal, config, workers) if warm is None else warm
        contact_plan = warm.contact_plan
    search_time = time.perf_counter() - t0 if warm is None else warm.total_time_s
    model = object_model(scene)
    common = dict(
        goal=goal, contact_plan=contact_plan, object_model=model, mu_plan=mu, search_time_s=search_time, method=method
    )
    common["formulation"] = "joint"  # one program over the horizon, as the plane's baselines record
    if not contact_plan.success or (warm is not None and warm.trajectory is None):
        return SpacePlanResult(
            success=False,
            status=("search: " + contact_plan.reason) if warm is None else ("warm start: " + warm.status),
            trajectory=None,
            physics_check=None,
            final_error_rad=float("nan"),
            segments=(),
            solve_time_s=0.0,
            total_time_s=search_time,
            **common,
        )
    t1 = time.perf_counter()
    hand = hand_model(scene)
    if warm is None:
        spec, start = cito_cold_start(hand, hand.chains, contact_plan.nodes[0], goal, mu)
    else:
        spec, start = cito_warm_start(hand, hand.chains, warm.trajectory, mu)
    result = solve_space_cito(hand, hand.chains, spec, mu, config.cito, start)
    return _checked(scene, [result], time.perf_counter() - t1, t1 - search_time, common)


def join_segments(scene, results) -> SpaceTrajectory:
    """One trajectory of the segments' knots, each segment after the last (a node is both one's last knot and
    the next one's first: kept once), and the link capsules' ends by the plant's kinematics."""
    parts = {name: [] for name in ("t", "x", "v", "q", "tau", "f_W", "p_W_C", "p_W_tip")}
    offset = 0.0
    for s, r in enumerate(results):
        first = 0 if s == 0 else 1
        for name in parts:
            value = getattr(r, name)[first:]
            parts[name].append(value + offset if name == "t" else value)
        offset += float(r.t[-1])
    arrays = {name: np.concatenate(values) for name, values in parts.items()}
    # a node where the switching finger lands carries both segments' forces: the later one's (both hold it still)
    return SpaceTrajectory(**arrays, p_W_links=scene.link_ends_W(arrays["x"], arrays["q"]))


PLAN_JSON, PLAN_NPZ = "plan.json", "plan.npz"


def save_space_plan(result: SpacePlanResult, folder: Path, config: Config) -> None:
    """folder/plan.json and, when something was solved, folder/plan.npz (the arrays by their names)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / PLAN_NPZ).unlink(missing_ok=True)
    if result.trajectory is not None:
        np.savez(folder / PLAN_NPZ, **result.trajectory.arrays())
    data = {**result.to_json(), "config": config_to_dict(config)}
    (folder / PLAN_JSON).write_text(json.dumps(data, indent=1) + "\n")


def recheck_space_plan(folder: Path) -> SpacePhysicsCheck:
    """The physics check redone from folder/plan.npz and the object folder/plan.json names; ConfigError naming
    the file and what does not fit (a missing array, arrays whose shapes disagree)."""
    from trajectotree.config import ConfigError
    from trajectotree.planning.physics import check_space_arrays
    from trajectotree.results import SPACE_TRAJECTORY_ARRAYS

    data = json.loads((folder / PLAN_JSON).read_text())
    with np.load(folder / PLAN_NPZ) as npz:
        missing = [name for name in SPACE_TRAJECTORY_ARRAYS if name not in npz.files]
        if missing:
            raise ConfigError(f"{str(folder / PLAN_NPZ)!r} lacks the array(s) {', '.join(missing)}")
        arrays = {name: npz[name] for name in SPACE_TRAJECTORY_ARRAYS}
    try:
        check_space_arrays(arrays)
    except ValueError as e:
        raise ConfigError(f"{str(folder / PLAN_NPZ)!r}: {e}") from None
    model = SpaceObjectModel.from_json(data["object"])
    return check_space_physics(arrays, model, data["object"]["mu_plan"])
