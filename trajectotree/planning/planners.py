"""The three planners of the paper as one function, `plan(scene=, goal=, method=, config=)`.

- "trajectotree": contact search (Algorithm 1), then the plan-constrained CITO
  (eqs. 11-19), initialized from the plan.
- "cito-warm": contact search, then the general CITO (eqs. 1-10), object poses and
  joint angles initialized from the plan (the contact constraints are not used).
- "cito": the general CITO initialized in static equilibrium over the whole horizon.
  It uses no search: its initial grasp q*_0 is the search's initial-grasp chooser's
  first choice for the goal (`initial_grasp_plan`; closed-form IK) and its incremental goals
  x*_n the same interpolated object path, so its total time is build + solve only;
  `contact_plan` then holds node 0 alone.

All three share the program builder, the cost (eq. 11), the friction cones at
mu_plan = search.friction_safety * scene.mu (`config.mu_plan`), the solver options, the
violation report and the physics check of the plan's arrays (trajectotree.planning.physics):
a converged plan that fails it (e.g. a fingertip pushing the box from a distance) is
reported with success False and the check's reason in its status. Times:
search_time_s (0 for cito), build_time_s (program and guess), solve_time_s (IPOPT),
total_time_s = their sum. TrajectoTree's default formulation, keyframes (cito.formulation),
solves one program per segment (trajectotree.planning.keyframes); its build and solve times are
summed over the segments' solves, its total is the search plus their wall-clock time.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Mapping
from concurrent.futures import Executor
from pathlib import Path

import numpy as np

from trajectotree.cito.fingers import near_pairs
from trajectotree.cito.guess import plan_guess, static_guess
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program, general_spec
from trajectotree.cito.solve import LogObserver, solve, violations
from trajectotree.cito.transition import check_plan, transition_spec
from trajectotree.config import Config, ConfigError, mu_plan, with_segments
from trajectotree.contact_plan import ContactNode, ContactPlan
from trajectotree.geometry import box_to_world
from trajectotree.planning.keyframes import plan_keyframes
from trajectotree.planning.physics import ObjectModel, check_physics
from trajectotree.planning.piece import trajectory as segment_trajectory
from trajectotree.planning.request import PlanRequest, as_config, check_plan_request
from trajectotree.planning.start import begin_at
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.results import METHODS, PlanResult, check_goal, check_method  # noqa: F401 (planners.METHODS)
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.plant import Scene
from trajectotree.search.grasp import FormClosure
from trajectotree.search.initial_grasp import GraspTables
from trajectotree.search.tree import choose_initial_grasp, find_contact_plan, object_path
from trajectotree.start import StartState


def plan(
    *,
    goal=None,
    method: str = "trajectotree",
    config: Config | str | Path | Mapping | None = None,
    scene: Scene | None = None,
    start: StartState | str | Path | Mapping | None = None,
    contact_plan: ContactPlan | None = None,
    segment_executor: Executor | None = None,
    segment_workers: int | None = None,
    grasp_tables: GraspTables | None = None,
    log_observer: LogObserver | None = None,
    first_segment_first: bool = False,
    first_segment_deadline_s: float | None = None,
) -> PlanResult:
    """Plans `goal` for the object with `method` ("trajectotree", "cito" or "cito-warm"): a
    rotation (rad in W, any number within +-20 pi: 2 pi is a full turn; the object keeps its
    position), a pose (x m, y m, theta rad) in W or a config.GoalPose (results.check_goal); None:
    config.goal. A goal position the hand cannot carry the object to is refused before planning
    (ConfigError, trajectotree.search.workspace). The path has search.num_nodes nodes, or as many
    as the goal's distance needs (config.segments_for); the result's config holds the goal and the
    number. `config` is a Config, the path of a YAML file or a mapping of its sections (None:
    Config(), the paper's scene), `scene` the plant built from config.scene (None: built here; pass
    one to reuse it). With a `start` (a measured StartState, a mapping as in start.json or the path
    of one) the plan begins there: its grasp roots the search, its joint angles are the first knot's,
    and `goal` is the object's final pose in W (StartRefused before any planning when the start cannot
    hold the object: trajectotree.planning.start). Without one, an object the hand cannot grasp at its
    initial pose or hold the weight of is refused before any planning, and one only four fingers hold
    is warned of (trajectotree.planning.request: the checks the CLI makes). A `contact_plan` may be given
    for the methods that use one (the search is then skipped; its time counts 0).
    TrajectoTree's keyframes formulation solves its segments on `segment_executor` (e.g. a
    persistent segment_pool.local_pool, or a Dask Client's get_executor()), else on
    `segment_workers` local processes (1: serially in this process, as a sweep's trial
    does; None: one per segment, at most one per core). `grasp_tables` keeps the ranked
    initial grasps for the next plan (without it the search ranks them, inside its time);
    `log_observer` watches each IPOPT solve run in this process (cito.solve.solve).
    `first_segment_first` (TrajectoTree's keyframes formulation only; a plan executed while it is
    solved, as replanning does) solves segment 0 before the others and records in the result's
    segment_ready_s when each segment was ready, counted from this call
    (keyframes.solve_first_segment_first), segment 0's solves stopped `first_segment_deadline_s` after
    this call began (None: unbounded)."""
    called = time.perf_counter()
    config = as_config(config)
    _check_first_segment_first(first_segment_first, method, config)
    request = check_plan_request(
        goal=goal,
        method=method,
        config=config,
        scene=scene,
        start=start,
        segment_workers=segment_workers,
        grasp_tables=grasp_tables,
        grasp_given=contact_plan is not None,
    )
    if request.warning is not None:
        warnings.warn(str(request.warning), stacklevel=2)
    return plan_request(
        request,
        contact_plan=contact_plan,
        segment_executor=segment_executor,
        grasp_tables=grasp_tables,
        log_observer=log_observer,
        first_segment_first=first_segment_first,
        first_segment_deadline_s=first_segment_deadline_s,
        called=called,
    )


def plan_request(
    request: PlanRequest,
    *,
    contact_plan: ContactPlan | None = None,
    segment_executor: Executor | None = None,
    grasp_tables: GraspTables | None = None,
    log_observer: LogObserver | None = None,
    first_segment_first: bool = False,
    first_segment_deadline_s: float | None = None,
    called: float | None = None,
) -> PlanResult:
    """plan() of a checked request (planning.request.check_plan_request, which the CLI calls itself
    before it takes its output folder); the other arguments as plan()'s. `called`: when the plan was
    asked for (time.perf_counter()), from which segment_ready_s counts (None: now)."""
    called = time.perf_counter() if called is None else called
    method, goal, config, scene, start = request.method, request.goal, request.config, request.scene, request.start
    segment_workers = request.segment_workers
    _check_first_segment_first(first_segment_first, method, config)
    search = with_segments(config.search, config.scene.initial_pose, goal)
    config = dataclasses.replace(config, goal=goal, search=search)
    search_time = 0.0
    if method == "cito":
        contact_plan = initial_grasp_plan(scene, goal, config, grasp_tables)
        if not contact_plan.success:
            return _unsolved(method, goal.theta, contact_plan.reason, 0.0, contact_plan, config)
    elif contact_plan is None:
        t0 = time.perf_counter()
        contact_plan = find_contact_plan(scene, goal, config.search, grasp_tables)
        search_time = time.perf_counter() - t0
        if not contact_plan.success:
            return _unsolved(
                method, goal.theta, f"search failed: {contact_plan.reason}", search_time, contact_plan, config
            )
    if start is not None:
        contact_plan = begin_at(contact_plan, start)
    check_plan(contact_plan, scene, min_nodes=1 if method == "cito" else 2)

    if method == "trajectotree" and config.cito.formulation == "keyframes":
        return plan_keyframes(
            scene,
            goal.theta,
            contact_plan,
            config,
            search_time,
            executor=segment_executor,
            workers=segment_workers,
            log_observer=log_observer,
            first_segment_first=first_segment_first,
            since=called,
            first_segment_deadline_s=first_segment_deadline_s,
        )
    t0 = time.perf_counter()
    body = BodyParams(scene, config.cito.sdf_sharpness, mu=mu_plan(config.scene, config.search))
    if method == "trajectotree":
        spec = transition_spec(contact_plan, radius=scene.tip_radius, config=config.cito)
        q_nodes = [node.q for node in contact_plan.nodes]  # the fingers kept apart: cito/fingers.py
        pairs = near_pairs(scene.fingers, q_nodes, scene.tip_radius)
        spec = dataclasses.replace(spec, finger_pairs=pairs, finger_nodes=tuple(q_nodes))
    else:
        node0 = contact_plan.nodes[0]
        path = (
            object_path(scene.config.initial_pose, goal, config.search.num_nodes)
            if method == "cito"
            else contact_plan.object_path
        )
        spec = general_spec(x0=node0.object_pose, q0=node0.q, config=config.cito, object_path=path)
    program = build_program(config.cito, spec, body)
    guess = static_guess(program.rows, spec) if method == "cito" else plan_guess(program.rows, spec, contact_plan)
    build_time = time.perf_counter() - t0

    outcome = solve(program, guess, config.cito, log_observer)
    sol = outcome.solution
    trajectory = segment_trajectory(program, sol, scene)
    check = check_physics(trajectory.arrays(), ObjectModel.from_scene(scene), body.mu)
    status = outcome.status
    if outcome.success and not check.passed:
        status = f"{outcome.status}, physics check failed: {check.reason}"
    converged = outcome.success and contact_plan.success
    return PlanResult(
        method=method,
        goal=goal.theta,
        success=converged and check.passed,
        converged=converged,
        status=status,
        search_time_s=search_time,
        build_time_s=build_time,
        solve_time_s=outcome.solve_time_s,
        total_time_s=search_time + build_time + outcome.solve_time_s,
        cost=outcome.cost,
        iterations=outcome.iterations,
        contact_plan=contact_plan,
        trajectory=trajectory,
        violations=violations(program, sol, scene),
        config=config,
        solver_timing=outcome.timing,
        physics_check=check,
    )


def _check_first_segment_first(first_segment_first: bool, method: str, config: Config) -> None:
    if first_segment_first and (method != "trajectotree" or config.cito.formulation != "keyframes"):
        raise ConfigError(
            field="cito.formulation",
            value=config.cito.formulation if method == "trajectotree" else method,
            problem=": a first-segment-first plan is TrajectoTree's keyframes formulation's",
            choices=("keyframes",),
        )


def initial_grasp_plan(scene: Scene, goal, config: Config, tables: GraspTables | None = None) -> ContactPlan:
    """A one-node ContactPlan with the initial grasp, for `cito` (which has no search):
    config.search.initial_arclengths, or else the search's initial-grasp chooser's first
    choice for this goal (trajectotree.search.tree.choose_initial_grasp: the best-ranked candidate
    whose fingers pass the search's cheap checks for the goal; the search itself may root at a
    later one). success False with the refusal when no grasp qualifies or a contact is out of reach."""
    c = scene.config
    boundary = c.shape
    mu = mu_plan(c, config.search)
    goal = check_goal(goal)
    chosen, refusal = choose_initial_grasp(scene, goal, config.search, tables)
    if chosen is None:
        return ContactPlan(goal=goal.theta, goal_position=goal.position, success=False, refusal=refusal, mu_plan=mu)
    arclengths = np.asarray(chosen, dtype=float) % boundary.perimeter
    points = [boundary.point(s) for s in arclengths]
    p_BC, n_B = np.array([p for p, _ in points]), np.array([n for _, n in points])
    hand = HandModel.from_scene(scene)
    x0 = np.asarray(c.initial_pose, dtype=float)
    q = [hand.ik(i, box_to_world(x0, p_BC[i] + scene.tip_radius * n_B[i])) for i in range(scene.num_fingers)]
    if any(qi is None for qi in q):
        return ContactPlan(
            goal=goal.theta,
            goal_position=goal.position,
            success=False,
            refusal=Refusal(RefusalKind.INITIAL_OUT_OF_REACH),
            mu_plan=mu,
        )
    closure = FormClosure(boundary, mu, config.search.min_closure_margin)
    node = ContactNode(
        object_pose=x0,
        q=np.concatenate(q),
        arclengths=arclengths,
        p_BC=p_BC,
        n_B=n_B,
        switching_finger=None,
        closure_margin=float(closure.check(arclengths).margin),
        required_mu=closure.required_mu(arclengths),
    )
    return ContactPlan(goal=goal.theta, goal_position=goal.position, success=True, nodes=(node,), mu_plan=closure.mu)


def _unsolved(method, goal, status, search_time, contact_plan, config) -> PlanResult:
    return PlanResult(
        method=method,
        goal=goal,
        success=False,
        status=status,
        search_time_s=search_time,
        build_time_s=0.0,
        solve_time_s=0.0,
        total_time_s=search_time,
        cost=float("nan"),
        iterations=0,
        contact_plan=contact_plan,
        trajectory=None,
        violations={},
        config=config,
    )
