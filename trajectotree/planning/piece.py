"""One piece of a keyframes plan: the program of nodes first..last (a segment, or a retry's range)
built and solved in one process (`solve_piece`, a worker's entry point), its arrays physics-checked;
a segment's first solve and its own retries in one task (`solve_chain`). A task and its result are
plain values, so that they pickle to any executor.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import os
import resource
import time
from dataclasses import dataclass

import numpy as np

from trajectotree.cito.fingers import near_pairs
from trajectotree.cito.guess import plan_guess, rest_to_rest_progress
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.links import LinkRows
from trajectotree.cito.program import build_program
from trajectotree.cito.solve import LogObserver, solve, violations
from trajectotree.cito.transition import piece_spec
from trajectotree.cito.variables import CitoVariables
from trajectotree.config import CitoConfig, SceneConfig
from trajectotree.contact_plan import ContactPlan
from trajectotree.planning.physics import ObjectModel, check_physics, contact_points, link_penetrations
from trajectotree.results import FINGER_OVERLAP_TOL, LINK_PENETRATION_TOL, PhysicsCheck, Trajectory
from trajectotree.scene.plant import Scene, build_scene, plant_key

WORKER_SCENES = 4  # scenes a worker process keeps built (a pool usually serves the plans of one scene)
STRICT_PINNING = 100.0  # a "strict" attempt's factor on cito.weight_contact_slack (a stricter program)
# m, a predicted segment's (cito.link_rows_predicted) fingers whose link rows are below this at either node get
# their rows in its first solve too: a finger holding the object while another moves pushed its link inside
# where the search left it 0.3-9.3 mm off the object (8 of 12 segments measured)
NEAR_NODE_M = 0.012


@dataclass(frozen=True)
class PieceTask:
    """One program of nodes first..last (plain values: it pickles to any executor)."""

    scene: SceneConfig
    cito: CitoConfig
    mu: float  # the planning friction mu_plan
    plan: ContactPlan
    first: int
    last: int
    kind: str  # "keyframes", "restart" (from `guess`), "links" (with the link rows),
    #                                   "joint" (with the neighbours)
    #                                   or "strict" (pinned fingers STRICT_PINNING times harder: alone or joint)
    guess: np.ndarray | None = None  # (K, KNOT_SIZE) initial guess (None: the plan's guess)
    # s, a time.perf_counter() value on this machine (the process that made the task, or a worker beside it)
    # at which IPOPT stops, for a solve with a deadline; None: never
    deadline: float | None = None
    link_fingers: tuple | None = None  # the fingers the attempt's link rows (if any) cover; None: every finger


@dataclass(frozen=True)
class PieceResult:
    first: int
    last: int
    kind: str
    success: bool  # IPOPT converged and the piece's arrays pass the physics check
    converged: bool
    status: str
    iterations: int
    cost: float
    build_time_s: float
    solve_time_s: float
    trajectory: Trajectory
    check: PhysicsCheck
    violations: dict
    timing: dict
    solution: np.ndarray  # (K, KNOT_SIZE) the last iterate, for a restart
    max_rss_mb: float  # MB, peak resident memory of the process that solved it
    pid: int
    # s, time.perf_counter() in the process that solved it when its build began (CLOCK_MONOTONIC on
    # Linux: comparable across the processes of this machine), to order the attempts of a plan
    started_s: float = float("nan")
    # s (time.perf_counter in the planning process), when the planning process had this result (run_pieces):
    # a first-segment-first plan times each segment's readiness from it
    finished_s: float = float("nan")

    def record(self) -> dict:
        return {
            "kind": self.kind,
            "nodes": [self.first, self.last],
            "success": self.success,
            "status": self.status,
            "iterations": self.iterations,
            "time_s": self.build_time_s + self.solve_time_s,
            "max_rss_mb": self.max_rss_mb,
            "pid": self.pid,
        }


def trajectory(program, sol, scene: Scene) -> Trajectory:
    """The plan.npz arrays of a solution; p_W_C from the planned contacts (pinned) and
    the box points nearest the fingertips (free)."""
    spec, kin = program.spec, program.rows.kinematics(sol.stacked())
    p_BC_planned = spec.c_B - scene.tip_radius * spec.n_B  # c_B is the fingertip centre's target
    c = scene.config
    p_W_C = contact_points(sol.x, kin.p_WF, spec.pinned, p_BC_planned, c.shape)
    return Trajectory(
        t=np.arange(spec.num_knots) * spec.dt,
        x=sol.x,
        xdot=sol.xd,
        q=sol.q,
        qdot=sol.qd,
        tau=sol.tau,
        lambda_n=sol.lambda_n,
        lambda_t=sol.lambda_t,
        f_W=kin.f_W,
        p_W_tip=kin.p_WF,
        p_W_C=p_W_C,
    )


def worker_scene(config: SceneConfig) -> Scene:
    """The scene a worker process solves `config`'s pieces in, on the plant built for the first piece of
    its plant_key and kept for the next ones (a forked worker inherits the ones its parent built): a
    replan's pieces (a new start pose, new estimates) plan on the plant of the plan before."""
    return _worker_plant(plant_key(config)).for_planning(config)


@functools.lru_cache(maxsize=WORKER_SCENES)
def _worker_plant(key: SceneConfig) -> Scene:
    return build_scene(key)


def finger_pairs(task: PieceTask, scene: Scene) -> tuple:
    """The pairs of fingers the piece's program keeps apart by finger rows: those that come near each
    other on the straight joint-space path between its nodes (cito.fingers.near_pairs), every pair in a
    "links" retry (it follows an attempt whose links or fingers overlapped)."""
    if task.kind == "links":
        return tuple(itertools.combinations(range(scene.num_fingers), 2))
    q_nodes = [node.q for node in task.plan.nodes[task.first : task.last + 1]]
    return near_pairs(scene.fingers, q_nodes, scene.tip_radius)


def solve_piece(task: PieceTask, scene: Scene | None = None, log_observer: LogObserver | None = None) -> PieceResult:
    """Builds and solves one piece in this process: in `scene` (built from task.scene), else in
    this process's worker_scene (a worker's entry point); `log_observer` watches its IPOPT solve."""
    scene = worker_scene(task.scene) if scene is None else scene
    t0 = time.perf_counter()
    body = BodyParams(scene, task.cito.sdf_sharpness, mu=task.mu)
    spec = piece_spec(task.plan, task.first, task.last, radius=scene.tip_radius, config=task.cito)
    q_nodes = tuple(node.q for node in task.plan.nodes[task.first : task.last + 1])  # a retry's middle nodes too
    spec = dataclasses.replace(
        spec, finger_pairs=finger_pairs(task, scene), finger_nodes=q_nodes, link_fingers=task.link_fingers
    )
    program = build_program(task.cito, spec, body)
    sub = dataclasses.replace(task.plan, nodes=task.plan.nodes[task.first : task.last + 1])
    guess = plan_guess(program.rows, spec, sub) if task.guess is None else CitoVariables.from_stacked(task.guess)
    build_time = time.perf_counter() - t0
    left = None if task.deadline is None else task.deadline - time.perf_counter()  # after the build
    outcome = solve(program, guess, task.cito, log_observer, left)
    arrays = trajectory(program, outcome.solution, scene)
    check = check_physics(arrays.arrays(), ObjectModel.from_scene(scene), body.mu)
    return PieceResult(
        first=task.first,
        last=task.last,
        kind=task.kind,
        success=outcome.success and check.passed,
        converged=outcome.success,
        status=outcome.status,
        iterations=outcome.iterations,
        cost=outcome.cost,
        build_time_s=build_time,
        solve_time_s=outcome.solve_time_s,
        trajectory=arrays,
        check=check,
        violations=violations(program, outcome.solution, scene),
        timing=outcome.timing,
        solution=outcome.solution.stacked(),
        max_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        pid=os.getpid(),
        started_s=t0,
    )


def predicted_link_fingers(task: PieceTask, scene: Scene) -> tuple[int, ...]:
    """The fingers whose link rows a segment's first solve gets (cito.link_rows_predicted; () : none): where
    the straight joint path between its two nodes, the object held at the first node's pose, puts a link
    inside the object, that path's fingers and those whose links are within NEAR_NODE_M of it at either node."""
    c = task.cito
    single = task.kind == "keyframes" and task.last == task.first + 1
    if not (single and c.link_rows and c.link_rows_on_demand and c.link_rows_predicted):
        return ()
    n0, n1 = task.plan.nodes[task.first], task.plan.nodes[task.last]
    depth = straight_path_link_depths(n0, n1, c.knots_per_segment, scene)  # the segment's knots (piece_spec)
    on_path = set(np.flatnonzero(depth.max(axis=(0, 2)) > 0.0))
    if not on_path:
        return ()
    body = BodyParams(scene, c.sdf_sharpness, mu=task.mu)
    near = {i for i in range(scene.num_fingers) if _node_clearance(body, i, (n0, n1)) < NEAR_NODE_M}
    return tuple(int(i) for i in sorted(on_path | near))


def straight_path_link_depths(n0, n1, knots: int, scene: Scene) -> np.ndarray:
    """(knots, F, L) m, how deep each finger's links are inside the object (physics.link_penetrations) along the
    straight joint-space path from node n0 to node n1 under the rest-to-rest time law, the object held at n0's pose."""
    u = rest_to_rest_progress(knots)
    q = n0.q + np.outer(u, n1.q - n0.q)
    return link_penetrations(np.tile(n0.object_pose, (len(u), 1)), q, scene.fingers, scene.config.shape)


def _node_clearance(body: BodyParams, finger: int, nodes) -> float:
    """m, the least of finger's link rows (smooth distances, as the program's) at the search's nodes."""
    rows = LinkRows(body, 1, (finger,))
    return min(float(rows.values_one(rows.block(n.object_pose, n.q)).min()) for n in nodes)


def attempt_config(cito: CitoConfig, kind: str, link_fingers: tuple | None = None) -> CitoConfig:
    """The CITO config of an attempt of `kind` in a plan of `cito`: a segment's first solve and its
    restart without the link rows when they come on demand (cito.link_rows_on_demand) and no
    `link_fingers` were predicted for it, a "strict" one with its pinned fingers held STRICT_PINNING
    times harder (cito.weight_contact_slack), the others (with the link rows where cito has them) as
    `cito`."""
    if kind in ("keyframes", "restart") and cito.link_rows and cito.link_rows_on_demand and not link_fingers:
        return dataclasses.replace(cito, link_rows=False)
    if kind == "strict":
        return dataclasses.replace(cito, weight_contact_slack=cito.weight_contact_slack * STRICT_PINNING)
    return cito


def solve_chain(
    task: PieceTask, scene: Scene | None = None, log_observer: LogObserver | None = None
) -> tuple[PieceResult, ...]:
    """A segment's attempts, in one task (solve_piece's arguments; task.cito is the plan's config,
    attempt_config derives each attempt's), so that its retries start as soon as it fails instead
    of after a round of every segment (issue 35): its first solve (task.kind); where IPOPT did not
    converge, again from the last iterate ("restart"); then, where a link overlaps the object or two
    fingers overlap and the link rows come on demand, with every row from the plan's guess
    ("links": from a link deep inside the object IPOPT may not recover); then, still failing, alone
    with its pinned fingers held harder ("strict", from the guess). No retry starts after the
    task's deadline. The first solve and its restart get the link rows of predicted_link_fingers."""
    scene = worker_scene(task.scene) if scene is None else scene
    predicted = predicted_link_fingers(task, scene) or None

    def attempt(kind: str, guess: np.ndarray | None, link_fingers: tuple | None = None) -> PieceResult:
        cito = attempt_config(task.cito, kind, link_fingers)
        retry = dataclasses.replace(task, kind=kind, cito=cito, guess=guess, link_fingers=link_fingers)
        return solve_piece(retry, scene, log_observer)

    def late() -> bool:
        return task.deadline is not None and time.perf_counter() >= task.deadline

    tried = [attempt(task.kind, task.guess, predicted)]
    if not tried[-1].converged and not late():
        tried.append(attempt("restart", tried[-1].solution, predicted))
    if task.cito.link_rows and task.cito.link_rows_on_demand and overlaps(tried[-1].check) and not late():
        tried.append(attempt("links", None))
    if not tried[-1].success and not late():
        tried.append(attempt("strict", None))
    return tuple(tried)


def overlaps(check: PhysicsCheck) -> bool:
    """A link inside the object or two fingers inside each other beyond the physics check's tolerances."""
    return check.link_penetration_m > LINK_PENETRATION_TOL or -check.finger_distance_m > FINGER_OVERLAP_TOL
