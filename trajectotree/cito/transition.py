"""The plan-constrained (TrajectoTree) program, paper eqs. 11-19, as a ProgramSpec.

Segment s = 0..N-2 joins nodes s and s+1 of the contact plan over knots
s M_hat .. (s+1) M_hat; consecutive segments share their boundary knot, so
K = (N-1) M_hat + 1 (the paper's M = (N-1) M_hat time steps). In segment s:
  - fixed fingers are pinned at their planned contacts at every knot (eq. 15);
  - the switching finger of node s+1 is pinned at its old contact at the first
    knot and at its new one at the last (eqs. 12-13), and free with the
    complementarity rows in between (eq. 14), lifted off the box by at least
    switch_clearance sin(pi j / M_hat) at its j-th knot, with no normal force while
    lifted (not in the paper, whose setting configs/paper.yaml restores with 0);
  - the object and joints are at rest at the segment's first and last knot
    (eqs. 18-19); x_0 and q_0 are fixed (eqs. 16-17);
  - the running pose cost targets x*_{s+1} (eq. 11).
Pinning means the fingertip centre sits at p*_BC + r n*_B in the box frame, relaxed
by the finger's penalized slack, with the planned contact frame.
`piece_spec` is the same program over some of the nodes with both ends fixed at them (the
keyframes formulation, trajectotree.planning.keyframes).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from trajectotree.cito.program import ProgramSpec
from trajectotree.config import CitoConfig, ConfigError
from trajectotree.contact_plan import ContactPlan


def check_plan(plan: ContactPlan, scene, min_nodes: int = 2) -> None:
    """Raises ConfigError when the plan cannot belong to this scene."""
    if len(plan.nodes) < min_nodes:
        raise ConfigError(f"contact plan has {len(plan.nodes)} nodes; at least {min_nodes} needed")
    c = scene.config
    if not np.allclose(plan.nodes[0].object_pose, c.initial_pose, atol=1e-9):
        raise ConfigError(
            f"contact plan starts at pose {list(plan.nodes[0].object_pose)}, the scene at {list(c.initial_pose)}"
        )
    F = scene.num_fingers
    for n, node in enumerate(plan.nodes):
        if np.shape(node.q) != (2 * F,) or np.shape(node.p_BC) != (F, 2):
            raise ConfigError(
                f"contact plan node {n} has q shape {np.shape(node.q)} and p_BC shape "
                f"{np.shape(node.p_BC)}; expected ({2 * F},) and ({F}, 2)"
            )
        # Every contact must lie on this scene's object boundary (the box's or the polygon's).
        if np.any(np.abs(c.shape.signed_distances(node.p_BC)) > 1e-6):
            raise ConfigError(
                f"contact plan node {n} has contacts {node.p_BC.tolist()} off the boundary of the "
                f"scene's object {_describe(c)}"
            )
        if node.switching_finger is not None and node.switching_finger not in range(F):
            raise ConfigError(
                f"contact plan node {n} has switching_finger {node.switching_finger}; valid: 0-{F - 1} or null"
            )


def _describe(c) -> str:
    if c.object.is_box:
        return f"(the {c.box_width} x {c.box_height} m box)"
    return f"(the polygon {np.round(c.shape.vertices, 6).tolist()} m)"


def transition_spec(plan: ContactPlan, *, radius: float, config: CitoConfig) -> ProgramSpec:
    """The TrajectoTree program's spec for a successful contact plan."""
    M = config.knots_per_segment
    N = len(plan.nodes)
    K = (N - 1) * M + 1
    F = len(plan.nodes[0].p_BC)
    pinned = np.ones((K, F), bool)
    c_B = np.zeros((K, F, 2))
    n_B = np.zeros((K, F, 2))
    clearance = np.zeros((K, F))
    lift = config.switch_clearance * np.sin(np.pi * np.arange(M + 1) / M)
    goals = [[] for _ in range(K)]
    for s in range(N - 1):
        old, new = plan.nodes[s], plan.nodes[s + 1]
        ks = np.arange(s * M, (s + 1) * M + 1)
        c_B[ks] = old.p_BC + radius * old.n_B
        n_B[ks] = old.n_B
        f = new.switching_finger
        if f is not None:
            pinned[ks[1:-1], f] = False
            clearance[ks[1:-1], f] = lift[1:-1]  # free knots only: pinned at both ends
        c_B[ks[-1]] = new.p_BC + radius * new.n_B
        n_B[ks[-1]] = new.n_B
        for k in ks:
            goals[k].append(new.object_pose)
    return ProgramSpec(
        dt=config.dt,
        pinned=pinned,
        c_B=c_B,
        n_B=n_B,
        clearance=clearance,
        x0=np.asarray(plan.nodes[0].object_pose, float),
        q0=np.asarray(plan.nodes[0].q, float),
        rest_knots=np.arange(0, K, M),
        goal_poses=tuple(np.array(g) for g in goals),
        segment_length=M,
    )


def piece_spec(plan: ContactPlan, first: int, last: int, *, radius: float, config: CitoConfig) -> ProgramSpec:
    """The keyframes formulation's program for nodes first..last of the plan (one segment when
    last = first + 1; more when a failed segment is retried with its neighbours): the
    transition program of those nodes with both end knots fixed at the nodes' poses and joint
    angles (each node's grasp is a static stance the search verified), at rest as in the joint
    program, and with zero object and hand accelerations there, so that the
    pieces' end knots are one state and their forces at the shared knot can be averaged."""
    sub = dataclasses.replace(plan, nodes=plan.nodes[first : last + 1])
    spec = transition_spec(sub, radius=radius, config=config)
    end = sub.nodes[-1]
    return dataclasses.replace(
        spec,
        x_end=np.asarray(end.object_pose, float),
        q_end=np.asarray(end.q, float),
        static_knots=(0, spec.num_knots - 1),
    )
