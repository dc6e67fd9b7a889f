"""Initial guesses: static equilibrium (`cito`) and from the contact plan
(`trajectotree`, `cito-warm`), both as CitoVariables of numbers.

Contact forces of a guess produce the guessed object acceleration with the fingers
that touch it: lambda = lambda_pref + G^+ (w - G lambda_pref), the least-change
solution of G lambda = w from a preferred squeeze lambda_n = m g per finger
(G: the grasp map of the touching fingers, w = M_obj x_dd - m g), clipped to the
friction cones. Torques then satisfy the hand dynamics: tau = M q_dd - tau_g + J_C^T f_W.
A guess that satisfies the dynamics rows lets IPOPT start nearly feasible.
"""

from __future__ import annotations

import numpy as np

from trajectotree.cito.knot import KnotRows
from trajectotree.cito.program import ProgramSpec
from trajectotree.cito.variables import CitoVariables
from trajectotree.contact_plan import ContactPlan
from trajectotree.geometry import ConvexPolygon, rotation_2d

# Height (m) the switching finger is lifted off the surface halfway through its
# move in the plan-based guess, so the guessed path does not cut through the object.
LIFT_HEIGHT = 0.015
# Initial slack value; IPOPT moves it into the interior of slack >= 0 anyway.
SLACK_GUESS = 1e-3


def static_guess(rows: KnotRows, spec: ProgramSpec) -> CitoVariables:
    """The object at x_0 and the hand at q_0 over the whole horizon, in static
    equilibrium (the paper's `cito` baseline initialization)."""
    K = spec.num_knots
    return _complete(rows, spec, np.tile(spec.x0, (K, 1)), np.tile(spec.q0, (K, 1)), moving=False)


def plan_guess(rows: KnotRows, spec: ProgramSpec, plan: ContactPlan) -> CitoVariables:
    """Object poses along the plan's path with a rest-to-rest time scaling per segment,
    joint angles by closed-form IK to the planned contacts (the switching finger
    following the object's boundary between its old and new contact, lifted off it), and
    static-equilibrium forces."""
    M = spec.segment_length
    progress = rest_to_rest_progress(M)
    x = np.vstack(
        [
            node.object_pose + np.outer(progress[:-1], nxt.object_pose - node.object_pose)
            for node, nxt in zip(plan.nodes[:-1], plan.nodes[1:])
        ]
        + [plan.nodes[-1].object_pose[None]]
    )
    hand, r, F = rows.body.hand, rows.body.radius, rows.layout.num_fingers
    boundary = rows.body.shape
    q = np.empty((spec.num_knots, 2 * F))
    for s in range(len(plan.nodes) - 1):
        old, new = plan.nodes[s], plan.nodes[s + 1]
        ks = s * M + np.arange(M + 1)
        for i in range(F):
            if i == new.switching_finger:
                c_B = [_lifted(boundary, old.arclengths[i], new.arclengths[i], u, r) for u in progress]
            else:
                c_B = [old.p_BC[i] + r * old.n_B[i]] * len(progress)
            # The segment's knots at once (one vectorized IK per finger, bit for bit the one-target IK).
            qi = hand.ik_many(i, np.array([x[k, :2] + rotation_2d(x[k, 2]) @ c for k, c in zip(ks, c_B)]))
            between = (1 - progress)[:, None] * old.q[2 * i : 2 * i + 2] + progress[:, None] * new.q[2 * i : 2 * i + 2]
            q[ks, 2 * i : 2 * i + 2] = np.where(np.isnan(qi[:, :1]), between, qi)
    return _complete(rows, spec, x, q, moving=True)


def rest_to_rest_progress(M: int) -> np.ndarray:
    """(M + 1,) progress 0 -> 1 over a segment of M steps, at rest at both ends: the
    trapezoidal integral of a sin^2 velocity bump."""
    v = np.sin(np.pi * np.arange(M + 1) / M) ** 2
    u = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]))])
    return u / u[-1]


def _lifted(boundary: ConvexPolygon, s_old: float, s_new: float, tau: float, radius: float) -> np.ndarray:
    """Fingertip centre in B for the switching finger at phase tau of its move: along
    the boundary the short way round, LIFT_HEIGHT off it at mid-move."""
    P = boundary.perimeter
    ds = (s_new - s_old + P / 2) % P - P / 2
    p, n = boundary.point(s_old + tau * ds)
    return p + (radius + LIFT_HEIGHT * np.sin(np.pi * tau)) * n


def _complete(rows: KnotRows, spec: ProgramSpec, x: np.ndarray, q: np.ndarray, *, moving: bool) -> CitoVariables:
    K, F = spec.num_knots, rows.layout.num_fingers
    x[0], q[0] = spec.x0, spec.q0
    if spec.x_end is not None:  # keyframes: the last knot is fixed too
        x[-1], q[-1] = spec.x_end, spec.q_end
    zeros = {name: np.zeros((K, w)) for name, w in rows.layout.block.groups}
    zeros.update(x=x, q=q, slack=np.full((K, F), SLACK_GUESS))
    if moving:
        for pos, vel, acc in (("x", "xd", "xdd"), ("q", "qd", "qdd")):
            zeros[vel] = np.gradient(zeros[pos], spec.dt, axis=0)
            zeros[vel][spec.rest_knots] = 0.0
            zeros[acc] = np.gradient(zeros[vel], spec.dt, axis=0)
            zeros[acc][list(spec.static_knots)] = 0.0
    guess = CitoVariables(**zeros)
    ln, lt = _static_forces(rows, guess)
    guess = CitoVariables(**{**zeros, "lambda_n": ln, "lambda_t": lt})
    kin = rows.kinematics(guess.stacked())
    hand, r = rows.body.hand, rows.body.radius
    JTf = np.einsum("kiab,kia->kib", kin.J, kin.f_W) - r * lt[..., None]
    Mqdd = np.einsum("kiab,kib->kia", hand.mass_matrices(q), guess.qdd.reshape(K, F, 2))
    tau = np.clip((Mqdd + JTf - hand.gravity_forces(q)).reshape(K, -1), -hand.tau_max, hand.tau_max)
    return CitoVariables(**{**zeros, "lambda_n": ln, "lambda_t": lt, "tau": tau})


def _static_forces(rows: KnotRows, guess: CitoVariables, touch_tol: float = 1e-3):
    """(lambda_n, lambda_t) (K, F) giving the object its guessed acceleration with the
    fingers that are pinned or within touch_tol of the surface."""
    b = rows.body
    kin = rows.kinematics(guess.stacked())
    touching = rows.pinned | (kin.phi_tip < touch_tol)  # (K, 4)
    cols_n = np.concatenate([-kin.n_W, _cross(kin.arm, -kin.n_W)[..., None]], axis=-1)  # (K, 4, 3)
    cols_t = np.concatenate([kin.t_W, _cross(kin.arm, kin.t_W)[..., None]], axis=-1)
    G = np.concatenate([cols_n * touching[..., None], cols_t * touching[..., None]], axis=1).transpose(0, 2, 1)
    weight = b.mass * np.linalg.norm(b.gravity)
    w = np.concatenate([b.mass * (guess.xdd[:, :2] - b.gravity), b.inertia * guess.xdd[:, 2:]], axis=1)
    pref = np.concatenate([weight * touching, np.zeros(touching.shape)], axis=1)
    lam = pref + np.einsum("kij,kj->ki", np.linalg.pinv(G), w - np.einsum("kij,kj->ki", G, pref))
    F = rows.layout.num_fingers
    ln = np.maximum(lam[:, :F], 0.0)
    return ln, np.clip(lam[:, F:], -b.mu * ln, b.mu * ln)


def _cross(a, f):
    return a[..., 0] * f[..., 1] - a[..., 1] * f[..., 0]
