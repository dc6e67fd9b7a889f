"""The joint formulation in space (the paper's): the search's segments in one IPOPT program over the whole
horizon (planning.spatial runs it with cito.formulation joint, `plan --formulation joint`).

Each segment keeps its rows (cito.spatial.SpaceSegmentRows: its contacts, its switching finger lifted, its pair
rows) over its knots of one z, a node both one segment's last knot and the next one's first (joint_knots); the
rule holds between every two knots. The start and the goal are pinned as a segment's ends are (pose, rest,
static, joints); every node between them is free (phi within PHI_BOUND, moving, its joints within their limits,
its links and fingers held apart as a free knot's), its knot rows bounded once, by the segment it ends. The
segment program's costs count once per knot.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from pydrake.solvers import MathematicalProgram

from trajectotree.cito.spatial import (
    NAMES,
    PHI_BOUND,
    SPACE_DT,
    SPACE_INTERVALS,
    SegmentConstraint,
    SegmentSpec,
    SpaceSegmentResult,
    SpaceSegmentRows,
    add_costs,
    add_rule,
    finger_overlap,
    guess,
    link_depth,
    near_apart,
    segment_arrays,
    solve_with_link_retry,
)
from trajectotree.config import CitoConfig


@dataclass(frozen=True)
class SpaceJointProgram:
    """The joint formulation's program: the segments' knots in one z, a node both one segment's last knot and the
    next one's first (joint_knots), the nodes free but the start and the goal."""

    prog: MathematicalProgram
    z: np.ndarray  # (S (K - 1) + 1, width)
    rows: tuple[SpaceSegmentRows, ...]  # per segment, over its knots of z
    build_time_s: float


def joint_knots(rows) -> list[slice]:
    """Each segment's knots in the joint program's z: segment s's first is segment s - 1's last."""
    step = rows[0].K - 1
    return [slice(s * step, s * step + r.K) for s, r in enumerate(rows)]


def _joint_bounds(rows: SpaceSegmentRows, s: int, num_segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Segment s's knot rows' bounds in the joint program: its first knot's rows are segment s - 1's last knot's
    (the same node, contacts and pyramids), left to that segment (unbounded: no redundant equality rows); a
    node inside the horizon is free, its links held off the box as the free knots' are."""
    lo, hi = rows.knot_bounds(free_last=s < num_segments - 1)
    if s > 0:
        lo[0], hi[0] = -np.inf, np.inf
    return lo, hi


def build_space_joint(
    scene, fingers, specs: list[SegmentSpec], mu: float, links: bool = False, start: np.ndarray | None = None
) -> SpaceJointProgram:
    """The joint formulation in space (the paper's): one program over the whole horizon with the search's contact
    plan: each segment's rows (SpaceSegmentRows: its contacts, its switching finger lifted) over its knots, the
    rule between every two knots, the start and the goal pinned as a segment's ends are (pose, rest, static,
    joints), every node between them free (phi within PHI_BOUND, moving, its joints within their limits); the
    segment program's costs once per knot. From `start` (knots, width), else from the segments' guesses."""
    t0 = time.perf_counter()
    rows = tuple(SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links) for spec in specs)
    knots = joint_knots(rows)
    if start is None:
        start = np.concatenate([guess(rows[0]), *(guess(r)[1:] for r in rows[1:])])
    rows = tuple(
        SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links, near_apart(r, start[k]))
        for spec, r, k in zip(specs, rows, knots)
    )
    lay, m = rows[0].layout, scene.object.mass
    K = knots[-1].stop
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(K, lay.width, "z")
    var = {name: z[:, lay.slice(name)] for name in (*NAMES, "lam", "q")}
    for r, knot in zip(rows, knots):
        add_rule(prog, {name: v[knot] for name, v in var.items()}, r, m)
    prog.AddBoundingBoxConstraint(-PHI_BOUND, PHI_BOUND, var["phi"][1:-1].ravel())
    for end, p in ((0, specs[0].p), (-1, specs[-1].p)):
        for name, value in (("phi", np.zeros(3)), ("p", p), ("w", np.zeros(3)), ("v", np.zeros(3))):
            prog.AddBoundingBoxConstraint(value, value, var[name][end])
        prog.AddBoundingBoxConstraint(np.r_[0.0, 0.0, m * rows[0].g], np.r_[0.0, 0.0, m * rows[0].g], var["F"][end])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), var["T"][end])
    lam_hi = np.full((K, lay.num_fingers, lay.edges), np.inf)
    for spec, knot in zip(specs, knots):
        if spec.switching is not None:
            lam_hi[knot.start + 1 : knot.stop - 1, spec.switching] = 0.0
    prog.AddBoundingBoxConstraint(np.zeros(lam_hi.size), lam_hi.ravel(), var["lam"].ravel())
    lower = np.concatenate([c.q_lower for c in scene.fingers])
    upper = np.concatenate([c.q_upper for c in scene.fingers])
    prog.AddBoundingBoxConstraint(np.tile(lower, K - 2), np.tile(upper, K - 2), var["q"][1:-1].ravel())
    prog.AddBoundingBoxConstraint(specs[0].q_a.ravel(), specs[0].q_a.ravel(), var["q"][0])
    prog.AddBoundingBoxConstraint(specs[-1].q_b.ravel(), specs[-1].q_b.ravel(), var["q"][-1])
    for s, (r, knot) in enumerate(zip(rows, knots)):
        constraint = SegmentConstraint(r)
        lo, hi = _joint_bounds(r, s, len(rows))
        pair = np.zeros(3 * (r.K - 1))
        binding = prog.AddConstraint(
            constraint,
            np.concatenate([lo.ravel(), pair]),
            np.concatenate([hi.ravel(), pair]),
            z[knot].ravel(),
            description=f"space segment {s}",
        )
        binding.evaluator().SetGradientSparsityPattern(constraint.sparsity())
    add_costs(prog, var, lay, K)
    prog.SetInitialGuess(z, start)
    return SpaceJointProgram(prog, z, rows, time.perf_counter() - t0)


def solve_space_joint(
    scene, fingers, specs: list[SegmentSpec], mu: float, config: CitoConfig
) -> list[SpaceSegmentResult]:
    """The joint formulation built and solved by IPOPT (cito.solve's options), as a segment is, again with the link
    rows from its solution when a link then reaches over 1 mm into the box; the solution as one
    SpaceSegmentResult per segment (each with the one program's status and times)."""
    program, result, Z, times = solve_with_link_retry(
        lambda links, Z: build_space_joint(scene, fingers, specs, mu, links, Z),
        lambda program, Z: max(
            max(link_depth(r, Z[k]), finger_overlap(r, Z[k])) for r, k in zip(program.rows, joint_knots(program.rows))
        ),
        config,
    )
    return [segment_arrays(r, Z[k], result, times) for r, k in zip(program.rows, joint_knots(program.rows))]
