"""TrajectoTree's keyframes formulation (cito.formulation: keyframes): one program per segment.

The joint formulation (the paper's) is one program over all N-1 segments, the segment-end
poses free. Here segment s's first and last knots are the search's nodes s and s+1: object
pose and joint angles fixed to the node's (each node's grasp is a static stance the search
verified), velocities zero as in the joint program, and accelerations zero too, so the end
knot is one static state in both segments that share it. The N-1 programs are then
independent: they are solved at once (local processes, a given executor, or serially) and
stitched into one trajectory of the joint program's size. At a shared knot x, q are equal
and the velocities zero; its forces, torques (and the accelerations, zero in both) are the
average of both segments': every row of that knot (Newton-Euler, the hand's dynamics, the
contact rows, the friction cones) is linear in them at the fixed state, and the trapezoidal
rule on either side sees the same zero acceleration, so the stitched arrays satisfy the
joint program's constraints wherever both segments do. The final pose is the goal node's.

The link rows (cito.link_rows) are added on demand (cito.link_rows_on_demand): a segment is
first solved without them and, when one of its links then overlaps the object (the physics
check's exact test), again with them from the plan's guess ("links"); a segment whose straight joint
path between its nodes already puts a link inside gets the rows of the fingers at risk in its first
solve (cito.link_rows_predicted, piece.predicted_link_fingers). The finger-finger rows
(cito/fingers.py) keep the pairs of fingers that come within cito.fingers.NEAR_MARGIN of each
other on the straight joint-space path between the piece's nodes apart from the first solve
(`finger_pairs`); a piece whose fingers then overlap (the physics check) is retried as "links"
too, with rows for every pair.

A segment that fails is retried: one IPOPT did not converge first from its last iterate
("restart": IPOPT's barrier and L-BFGS memory start afresh; a converged one would only converge
there again), then, with a link or finger overlapping, with the link rows ("links", above), then,
still failing or converged with arrays that fail the physics check, alone with its pinned fingers
held STRICT_PINNING times harder ("strict": cito.weight_contact_slack x 100). These attempts run
in the segment's own task (piece.solve_chain), so a segment's retry starts as soon as it failed
and no segment waits for a round of the others' (issue 35: rounds made every retry wait for the
slowest segment). One whose chain still fails is solved with the joint formulation over it and
its neighbours ("joint": nodes s-1..s+2, ends still fixed at those nodes), which frees the two
keyframes next to it, and if that fails too, so again with its pinned fingers held harder
("strict"); not in a plan executed while it is solved (solve_first_segment_first), whose segments
may be executing by then. The L1 penalty on a pinned fingertip's drift off its contact
is exact only above the pinning constraint's multiplier; below it a fixed finger may drift 1 mm
and push from there (goal pi/2, the demo's: 9.35 N from 0.19 mm). As the default for every
segment that weight doubled the iterations on 24 seed-0 goals and broke one, hence only here.
Every attempt is recorded.
"""

from __future__ import annotations

import dataclasses
import math
import time
from concurrent.futures import Executor

import numpy as np

from trajectotree.cito.solve import LogObserver
from trajectotree.config import Config, mu_plan
from trajectotree.contact_plan import ContactPlan
from trajectotree.planning.physics import ObjectModel, check_physics
from trajectotree.planning.piece import PieceResult, PieceTask, attempt_config
from trajectotree.planning.segment_pool import run_chains, run_pieces
from trajectotree.results import PlanResult, Trajectory
from trajectotree.scene.plant import Scene

AVERAGED = ("tau", "lambda_n", "lambda_t", "f_W")  # the shared knot's forces: the mean of both segments'
SHARED = ("x", "xdot", "q", "qdot", "p_W_tip", "p_W_C")  # equal in both segments at a shared knot


def _neighbour_ranges(failed: list[int], n: int) -> list[tuple[int, int]]:
    """Node ranges (first, last) of the joint retries: each failed segment with its neighbours,
    overlapping ranges merged; ranges of one segment dropped (a joint retry of one segment frees
    nothing, and its chain made the strict attempt of it alone)."""
    merged = []
    for s in sorted(failed):
        a, b = max(s - 1, 0), min(s + 2, n)
        if merged and a < merged[-1][1]:  # ranges that only meet at a node stay apart
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]))
        else:
            merged.append((a, b))
    return [r for r in merged if r[1] - r[0] >= 2]


def solve_segments(
    plan: ContactPlan,
    config: Config,
    executor: Executor | None = None,
    workers: int | None = None,
    *,
    scene: Scene | None = None,
    log_observer: LogObserver | None = None,
    deadline: float | None = None,
    joint_retries: bool = True,
) -> tuple[list[PieceResult], dict[int, list[PieceResult]]]:
    """(the pieces to stitch, in order; every attempt per segment): each segment's chain of
    attempts (piece.solve_chain), then, with `joint_retries`, the joint retries of the segments
    whose chain failed; pieces solved in this process use `scene` when given (run_pieces). With a
    `deadline` (a time.perf_counter() value) each solve stops there and no retry starts after it."""
    n = len(plan.nodes) - 1
    mu = mu_plan(config.scene, config.search)

    def task(first: int, last: int, kind: str) -> PieceTask:
        # a chain ("keyframes") derives each attempt's config from the plan's (attempt_config)
        cito = config.cito if kind == "keyframes" else attempt_config(config.cito, kind)
        return PieceTask(config.scene, cito, mu, plan, first, last, kind, None, deadline)

    def late() -> bool:
        return deadline is not None and time.perf_counter() >= deadline

    chains = run_chains([task(s, s + 1, "keyframes") for s in range(n)], executor, workers, scene, log_observer)
    attempts = {s: list(chain) for s, chain in enumerate(chains)}
    pieces = {s: chain[-1] for s, chain in enumerate(chains)}  # keyed by each piece's first node
    for kind in ("joint", "strict") if joint_retries else ():
        if late():
            break
        failed = [s for s, p in sorted(pieces.items()) if not p.success]  # single segments: a joint piece passed
        ranges = _neighbour_ranges(failed, n)
        joint = run_pieces([task(a, b, kind) for a, b in ranges], executor, workers, scene, log_observer)
        for (a, b), r in zip(ranges, joint):
            for s in range(a, b):
                attempts[s].append(r)
            if r.success:
                for s in range(a, b):
                    pieces.pop(s, None)
                pieces[a] = r
    return [pieces[s] for s in sorted(pieces)], attempts


def stitch(pieces: list[PieceResult]) -> Trajectory:
    """One trajectory from consecutive pieces: each shared knot once, its forces averaged."""
    arrays = {name: [getattr(pieces[0].trajectory, name)] for name in SHARED + AVERAGED}
    for prev, piece in zip(pieces[:-1], pieces[1:]):
        a, b = prev.trajectory, piece.trajectory
        for name in SHARED:
            if not np.array_equal(getattr(a, name)[-1], getattr(b, name)[0]):
                raise AssertionError(f"pieces at nodes {prev.last} differ in {name}: a bug in the keyframes bounds")
            arrays[name].append(getattr(b, name)[1:])
        for name in AVERAGED:
            arrays[name][-1] = arrays[name][-1].copy()
            arrays[name][-1][-1] = 0.5 * (getattr(a, name)[-1] + getattr(b, name)[0])
            arrays[name].append(getattr(b, name)[1:])
    out = {name: np.concatenate(parts) for name, parts in arrays.items()}
    dt = pieces[0].trajectory.t[1] - pieces[0].trajectory.t[0]
    return Trajectory(t=np.arange(len(out["x"])) * dt, **out)


def segment_records(attempts: dict[int, list[PieceResult]], pieces: list[PieceResult]) -> tuple[dict, ...]:
    """plan.json's "segments": per segment its final attempt's status, its attempts' iterations
    and time summed (a joint retry is listed under each segment it covers), and the retries."""
    final = {s: p for p in pieces for s in range(p.first, p.last)}
    return tuple(
        {
            "nodes": [s, s + 1],
            "success": final[s].success,
            "status": final[s].status,
            "iterations": sum(r.iterations for r in tried),
            "time_s": sum(r.build_time_s + r.solve_time_s for r in tried),
            "retries": len(tried) - 1,
            "attempts": [r.record() for r in tried],
        }
        for s, tried in sorted(attempts.items())
    )


def plan_keyframes(
    scene: Scene,
    goal: float,
    contact_plan: ContactPlan,
    config: Config,
    search_time: float,
    executor: Executor | None = None,
    workers: int | None = None,
    log_observer: LogObserver | None = None,
    first_segment_first: bool = False,
    since: float | None = None,
    first_segment_deadline_s: float | None = None,
) -> PlanResult:
    """The trajectotree PlanResult of the keyframes formulation for a successful contact plan;
    first_segment_first solves it as solve_first_segment_first does, its segment_ready_s counted
    from `since` (a time.perf_counter() value; default: now), segment 0 ready within
    `first_segment_deadline_s` of it (None: unbounded).
    Times: build_time_s and solve_time_s summed over every attempt (process time in the
    workers); total_time_s = search_time + the wall-clock time of all segment solves. cost: the
    stitched pieces' costs summed (a shared knot's effort terms count in both); iterations: every
    attempt's; violations: each group's largest over the pieces."""
    t0 = time.perf_counter()
    since = t0 if since is None else since
    ready = ()
    if first_segment_first:
        pieces, attempts, ready = solve_first_segment_first(
            contact_plan,
            config,
            executor,
            workers,
            scene=scene,
            log_observer=log_observer,
            since=since,
            first_deadline_s=first_segment_deadline_s,
        )
        if not pieces[0].success:  # the rest is not solved: nothing of this plan can be executed
            return _first_segment_failed(scene, goal, contact_plan, config, search_time, attempts, ready, t0)
    else:
        pieces, attempts = solve_segments(
            contact_plan, config, executor, workers, scene=scene, log_observer=log_observer
        )
    wall = time.perf_counter() - t0
    distinct = list({id(r): r for tried in attempts.values() for r in tried}.values())
    arrays = stitch(pieces)
    check = check_physics(arrays.arrays(), ObjectModel.from_scene(scene), mu_plan(config.scene, config.search))
    converged = all(p.converged for p in pieces)
    failed = [p for p in pieces if not p.success]
    status = ", ".join(sorted({p.status for p in pieces}))
    if failed:
        p = failed[0]
        why = p.status if not p.converged else f"physics check failed: {p.check.reason}"
        status = (
            f"{len(failed)} of {len(pieces)} pieces failed after retries; nodes {p.first}-{p.last} ({p.kind}): {why}"
        )
    elif not check.passed:
        status = f"{status}, physics check failed: {check.reason}"
    timing = {}
    for r in distinct:
        for key, value in r.timing.items():
            timing[key] = timing.get(key, 0.0) + value
    groups = pieces[0].violations.keys()
    return PlanResult(
        method="trajectotree",
        goal=goal,
        success=converged and not failed and check.passed,
        converged=converged,
        status=status,
        search_time_s=search_time,
        build_time_s=sum(r.build_time_s for r in distinct),
        solve_time_s=sum(r.solve_time_s for r in distinct),
        total_time_s=search_time + wall,
        cost=float(sum(p.cost for p in pieces)),
        iterations=sum(r.iterations for r in distinct),
        contact_plan=contact_plan,
        trajectory=arrays,
        violations={g: max(p.violations[g] for p in pieces) for g in groups},
        config=config,
        solver_timing=timing,
        physics_check=check,
        formulation="keyframes",
        segments=segment_records(attempts, pieces),
        segment_ready_s=ready,
    )


def _first_segment_failed(scene, goal, contact_plan, config, search_time, attempts, ready, t0) -> PlanResult:
    """The PlanResult of a first-segment-first plan whose first segment failed after its retries (`attempts`:
    segment 0's, which its segment records list)."""
    first = attempts[0][-1]
    why = first.status if not first.converged else f"physics check failed: {first.check.reason}"
    return PlanResult(
        method="trajectotree",
        goal=goal,
        success=False,
        converged=first.converged,
        status=f"the first segment failed after retries ({first.kind}): {why}",
        search_time_s=search_time,
        build_time_s=first.build_time_s,
        solve_time_s=first.solve_time_s,
        total_time_s=search_time + time.perf_counter() - t0,
        cost=float("nan"),
        iterations=first.iterations,
        contact_plan=contact_plan,
        trajectory=None,
        violations=first.violations,
        config=config,
        formulation="keyframes",
        segments=segment_records(attempts, [first]),
        segment_ready_s=ready,
    )


def solve_first_segment_first(
    plan: ContactPlan,
    config: Config,
    executor: Executor | None = None,
    workers: int | None = None,
    *,
    scene: Scene | None = None,
    log_observer: LogObserver | None = None,
    since: float,
    first_deadline_s: float | None = None,
) -> tuple[list[PieceResult], dict[int, list[PieceResult]], tuple[float, ...]]:
    """solve_segments for a plan that is executed while it is being solved (replanning): segment 0
    first, alone, in this process (its retries too: restart, links, strict), then, if it passed,
    segments 1.. on `executor` / `workers`, each with its own chain of attempts and no joint retry
    (one would replace a segment that may be executing by then: a plan whose chain failed is executed
    up to that segment). Also returns when each segment was ready, in s after `since` (a
    time.perf_counter() value), inf for one that cannot be executed: each segment when its own last
    attempt came back (no neighbour's retry replaces it, so none waits for a neighbour: issue 35's
    mid-way holds); after the first segment that failed, none (an executor cannot skip a segment).
    Segment 0 must be ready within `first_deadline_s` of `since` (solve_segments' deadline: its
    attempts stop there), so the hand does not hold for long."""
    deadline = None if first_deadline_s is None else since + first_deadline_s
    first, first_attempts = solve_segments(
        dataclasses.replace(plan, nodes=plan.nodes[:2]),
        config,
        None,
        1,
        scene=scene,
        log_observer=log_observer,
        deadline=deadline,
    )
    n = len(plan.nodes) - 1
    ready = [max(r.finished_s for r in first_attempts[0]) - since]
    if not first[0].success or n == 1:
        return first, first_attempts, tuple(ready + [math.inf] * (n - 1))
    rest, rest_attempts = solve_segments(
        dataclasses.replace(plan, nodes=plan.nodes[1:]),
        config,
        executor,
        workers,
        scene=scene,
        log_observer=log_observer,
        joint_retries=False,
    )
    failed = False
    for s in range(n - 1):  # the rest's segment s is the plan's s + 1
        failed = failed or not rest[s].success
        ready.append(math.inf if failed else max(r.finished_s for r in rest_attempts[s]) - since)
    shifted = {}  # id -> the attempt with the plan's node numbers (a piece is its chain's last attempt: one copy)

    def moved(r: PieceResult) -> PieceResult:
        return shifted.setdefault(id(r), dataclasses.replace(r, first=r.first + 1, last=r.last + 1))

    attempts = {0: first_attempts[0]} | {s + 1: [moved(r) for r in tried] for s, tried in rest_attempts.items()}
    return first + [moved(p) for p in rest], attempts, tuple(ready)
