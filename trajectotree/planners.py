"""The three planners of the paper as one function, `plan(scene=, goal=, method=, config=)`.

- "trajectotree": contact search (Algorithm 1), then the plan-constrained CITO
  (eqs. 11-19), initialized from the plan.
- "cito-warm": contact search, then the general CITO (eqs. 1-10), object poses and
  joint angles initialized from the plan (the contact constraints are not used).
- "cito": the general CITO initialized in static equilibrium over the whole horizon.
  It uses no search: its initial grasp q*_0 is the search's initial-grasp chooser's
  first choice for the goal (`initial_grasp_plan`; closed-form IK) and its incremental goals x*_n the same interpolated object path,
  so its total time is build + solve only; `contact_plan` then holds node 0 alone.

All three share the program builder, the cost (eq. 11), the friction cones at
mu_plan = search.friction_safety * scene.mu (`planning_mu`), the solver options, the
violation report and the physics check of the plan's arrays (trajectotree.physics):
a converged plan that fails it (e.g. a fingertip pushing the box from a distance) is
reported with success False and the check's reason in its status. Times:
search_time_s (0 for cito), build_time_s (program and guess), solve_time_s (IPOPT),
total_time_s = their sum.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from trajectotree.cito.guess import plan_guess, static_guess
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program, general_spec
from trajectotree.cito.solve import solve, violations
from trajectotree.cito.transition import check_plan, transition_spec
from trajectotree.config import Config, ConfigError
from trajectotree.contact_plan import ContactNode, ContactPlan
from trajectotree.geometry import BoxBoundary, box_to_world
from trajectotree.physics import BoxModel, PhysicsCheck, check_physics, contact_points
from trajectotree.scene import NUM_FINGERS, Scene

METHODS = ("trajectotree", "cito", "cito-warm")
TRAJECTORY_ARRAYS = ("t", "x", "xdot", "q", "qdot", "tau", "lambda_n", "lambda_t", "f_W", "p_W_tip", "p_W_C")


@dataclass(frozen=True)
class Trajectory:
    """The plan at every knot (the plan.npz arrays)."""

    t: np.ndarray          # (K,) s
    x: np.ndarray          # (K, 3) object pose (x m, y m, theta rad)
    xdot: np.ndarray       # (K, 3)
    q: np.ndarray          # (K, 8) rad, finger-major
    qdot: np.ndarray       # (K, 8) rad/s
    tau: np.ndarray        # (K, 8) N m
    lambda_n: np.ndarray   # (K, 4) N, normal force of each finger on the box
    lambda_t: np.ndarray   # (K, 4) N, tangential force (along t_B = z x n_B)
    f_W: np.ndarray        # (K, 4, 2) N, force of each finger ON the box, in W
    p_W_tip: np.ndarray    # (K, 4, 2) m, fingertip positions in W: the sphere centres
    #                        (finger{i}_tip frames)
    p_W_C: np.ndarray      # (K, 4, 2) m, where each finger's force acts on the box surface, in W: the
    #                        planned contact of a pinned finger, else the box point nearest the tip

    def arrays(self) -> dict[str, np.ndarray]:
        """{plan.npz name: array}."""
        return {name: getattr(self, name) for name in TRAJECTORY_ARRAYS}


@dataclass(frozen=True)
class PlanResult:
    method: str
    goal: float                      # rad
    success: bool                    # IPOPT converged, the physics check passed (the search too, where used)
    status: str                      # IPOPT status name (+ why the physics check failed), or why the search failed
    search_time_s: float
    build_time_s: float
    solve_time_s: float
    total_time_s: float
    cost: float                      # final objective (nan when nothing was solved)
    iterations: int                  # IPOPT iterations (0 when nothing was solved)
    contact_plan: ContactPlan
    trajectory: Trajectory | None    # None when nothing was solved
    violations: dict                 # max abs violation per group (solve.VIOLATION_GROUPS)
    config: Config
    solver_timing: dict = field(default_factory=dict)  # IPOPT's timing statistics, s
    physics_check: PhysicsCheck | None = None          # the check of the plan's arrays (None: nothing solved)
    # IPOPT converged (and the search found a plan, where used), whether or not the physics check
    # passed: the general CITO baselines converge to plans that push from a distance.
    converged: bool = False


def planning_mu(config: Config) -> float:
    """mu_plan = search.friction_safety * scene.mu, the friction every plan may use (the
    search's grasps and stances and the CITO friction cones: one definition for both)."""
    from trajectotree.initial_grasp import mu_plan
    return mu_plan(config.scene, config.search)


def check_method(method: str) -> str:
    if method not in METHODS:
        raise ConfigError(f"method = {method!r} is unknown; valid: {', '.join(METHODS)}")
    return method


def check_goal(goal) -> float:
    if isinstance(goal, bool) or not isinstance(goal, (int, float, np.floating)) or not math.isfinite(goal) \
            or abs(goal) > math.pi + 1e-9:
        raise ConfigError(f"goal = {goal!r} is out of range; valid range: [-pi, pi] rad")
    return float(goal)


def plan(*, scene: Scene, goal: float, method: str, config: Config,
         contact_plan: ContactPlan | None = None) -> PlanResult:
    """Plans the rotation `goal` (rad) with `method`. A `contact_plan` may be given
    for the methods that use one (the search is then skipped; its time counts 0)."""
    check_method(method)
    goal = check_goal(goal)
    if scene.config != config.scene:
        raise ConfigError("scene was built from a different SceneConfig than config.scene")
    search_time = 0.0
    if method == "cito":
        contact_plan = initial_grasp_plan(scene, goal, config)
        if not contact_plan.success:
            return _unsolved(method, goal, contact_plan.reason, 0.0, contact_plan, config)
    elif contact_plan is None:
        from trajectotree.search import find_contact_plan
        t0 = time.perf_counter()
        contact_plan = find_contact_plan(scene, goal, config.search)
        search_time = time.perf_counter() - t0
        if not contact_plan.success:
            return _unsolved(method, goal, f"search failed: {contact_plan.reason}", search_time, contact_plan, config)
    check_plan(contact_plan, scene, min_nodes=1 if method == "cito" else 2)

    t0 = time.perf_counter()
    body = BodyParams(scene, config.cito.sdf_sharpness, mu=planning_mu(config))
    if method == "trajectotree":
        spec = transition_spec(contact_plan, radius=scene.tip_radius, config=config.cito)
    else:
        node0 = contact_plan.nodes[0]
        path = _object_path(scene, goal, config) if method == "cito" else contact_plan.object_path
        spec = general_spec(x0=node0.object_pose, q0=node0.q, config=config.cito, object_path=path)
    program = build_program(config.cito, spec, body)
    guess = static_guess(program.rows, spec) if method == "cito" else plan_guess(program.rows, spec, contact_plan)
    build_time = time.perf_counter() - t0

    outcome = solve(program, guess, config.cito)
    sol = outcome.solution
    trajectory = _trajectory(program, sol, scene)
    check = check_physics(trajectory.arrays(), BoxModel.from_scene(scene), body.mu)
    status = outcome.status
    if outcome.success and not check.passed:
        status = f"{outcome.status}, physics check failed: {check.reason}"
    converged = outcome.success and contact_plan.success
    return PlanResult(method=method, goal=goal, success=converged and check.passed, converged=converged,
                      status=status, search_time_s=search_time, build_time_s=build_time,
                      solve_time_s=outcome.solve_time_s, total_time_s=search_time + build_time + outcome.solve_time_s,
                      cost=outcome.cost, iterations=outcome.iterations, contact_plan=contact_plan,
                      trajectory=trajectory, violations=violations(program, sol, scene), config=config,
                      solver_timing=outcome.timing, physics_check=check)


def _trajectory(program, sol, scene: Scene) -> Trajectory:
    """The plan.npz arrays of a solution; p_W_C from the planned contacts (pinned) and
    the box points nearest the fingertips (free)."""
    spec, kin = program.spec, program.rows.kinematics(sol.stacked())
    p_BC_planned = spec.c_B - scene.tip_radius * spec.n_B          # c_B is the fingertip centre's target
    c = scene.config
    p_W_C = contact_points(sol.x, kin.p_WF, spec.pinned, p_BC_planned, c.box_width, c.box_height)
    return Trajectory(t=np.arange(spec.num_knots) * spec.dt, x=sol.x, xdot=sol.xd, q=sol.q, qdot=sol.qd,
                      tau=sol.tau, lambda_n=sol.lambda_n, lambda_t=sol.lambda_t, f_W=kin.f_W, p_W_tip=kin.p_WF,
                      p_W_C=p_W_C)


def _object_path(scene: Scene, goal: float, config: Config) -> np.ndarray:
    """x*_0..x*_{N-1}: linear interpolation from the initial pose to the goal rotation
    (the same path the contact search uses)."""
    x0 = np.asarray(scene.config.initial_pose, dtype=float)
    return x0 + np.outer(np.linspace(0.0, 1.0, config.search.num_nodes), [0.0, 0.0, goal])


def initial_grasp_plan(scene: Scene, goal: float, config: Config) -> ContactPlan:
    """A one-node ContactPlan with the initial grasp, for `cito` (which has no search):
    config.search.initial_arclengths, or else the search's initial-grasp chooser's first
    choice for this goal (trajectotree.search.choose_initial_grasp: the best-ranked candidate
    whose fingers pass the search's cheap checks for the goal; the search itself may root at a
    later one). success False with the reason when no grasp qualifies or a contact is out of reach."""
    from trajectotree.grasp import FormClosure
    from trajectotree.initial_grasp import mu_plan
    from trajectotree.search import choose_initial_grasp
    from trajectotree.cito.hand import HandModel
    c = scene.config
    boundary = BoxBoundary(c.box_width, c.box_height)
    chosen, reason = choose_initial_grasp(scene, goal, config.search)
    if chosen is None:
        return ContactPlan(goal=goal, success=False, reason=reason, mu_plan=mu_plan(c, config.search))
    arclengths = np.asarray(chosen, dtype=float) % boundary.perimeter
    points = [boundary.point(s) for s in arclengths]
    p_BC, n_B = np.array([p for p, _ in points]), np.array([n for _, n in points])
    hand = HandModel.from_scene(scene)
    x0 = np.asarray(c.initial_pose, dtype=float)
    q = [hand.ik(i, box_to_world(x0, p_BC[i] + scene.tip_radius * n_B[i])) for i in range(NUM_FINGERS)]
    if any(qi is None for qi in q):
        return ContactPlan(goal=goal, success=False, reason="initial grasp out of reach of the fingers")
    closure = FormClosure(boundary, mu_plan(c, config.search), config.search.min_closure_margin)
    node = ContactNode(object_pose=x0, q=np.concatenate(q), arclengths=arclengths, p_BC=p_BC, n_B=n_B,
                       switching_finger=None, closure_margin=float(closure.check(arclengths).margin),
                       required_mu=closure.required_mu(arclengths))
    return ContactPlan(goal=goal, success=True, reason="", nodes=(node,), mu_plan=closure.mu)


def _unsolved(method, goal, status, search_time, contact_plan, config) -> PlanResult:
    return PlanResult(method=method, goal=goal, success=False, status=status, search_time_s=search_time,
                      build_time_s=0.0, solve_time_s=0.0, total_time_s=search_time, cost=float("nan"),
                      iterations=0, contact_plan=contact_plan, trajectory=None,
                      violations={}, config=config)
