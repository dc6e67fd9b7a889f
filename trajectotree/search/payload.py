"""The heaviest object the hand can carry from its candidate initial grasps, from the hand alone.

Two limits, both at the initial pose x_0, with friction mu_plan (the plans' cones), each joint's
torque within its actuator's effort limit (1 N m on this hand) after carrying its own links'
weight, and both maximised over the grasps the search may be rooted at (initial_grasp's
candidates, or search.initial_arclengths):

  - hold: the most weight all fingers of a grasp carry at rest. A heavier object cannot
    be held where every plan and every run starts, so no plan exists (what the motors cannot
    carry);
  - switch: the most weight three fingers of a grasp carry while the fourth lets go (a stance
    in closure at mu_plan, as the search requires), within search.max_stance_force in total
    normal force as well when that cap is set. The search refuses every switch of a heavier
    object at its first node, so only a plan that never switches a finger (a small rotation
    all fingers roll the object through) can exist.

Each limit is one LP per grasp or stance (maximize the weight W over the cone-edge
magnitudes x >= 0: E x = (0, W, 0) the wrench that holds the object, |J_C^T f - tau_g| <=
tau_max at every joint, sum lambda_n <= cap), each built once and solved per grasp or stance
(Clp, through Drake). J_C is the contact point's Jacobian on the finger's
second link; tau_g the links' generalized gravity forces in closed form (scene.dynamics.HandModel,
the plant's CalcGravityGeneralizedForces to 1e-16 N m on the planar hands). The object's mass
enters neither: the limits are weights, divided by scene.gravity into kg.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.solvers import ClpSolver, MathematicalProgram, SolverOptions

from trajectotree.config import SearchConfig, mu_plan
from trajectotree.geometry import rotation_2d
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.kinematics import K90
from trajectotree.scene.plant import Scene
from trajectotree.search.initial_grasp import GraspCandidates, initial_grasp_candidates, stance_fingers
from trajectotree.search.reach import Reachability


@dataclass(frozen=True)
class Payload:
    """The heaviest object (kg) the hand carries from its initial grasps (module docstring)."""

    hold_kg: float  # all fingers at rest at the initial pose, within the torque limits
    switch_kg: float  # three fingers while the fourth lets go, within the torque limits and the force cap
    max_stance_force: float  # N, the search's cap the switch limit obeys (0: none)
    tau_max: float  # N m, the largest joint effort limit of the hand
    grasps: int  # initial grasps the limits are maximised over

    def to_json(self) -> dict:
        return {
            "hold_kg": self.hold_kg,
            "switch_kg": self.switch_kg,
            "max_stance_force_N": self.max_stance_force,
            "tau_max_Nm": self.tau_max,
            "grasps": self.grasps,
        }


def payload(
    scene: Scene, search: SearchConfig, grasps: GraspCandidates | None = None, first: int | None = None
) -> Payload | None:
    """The Payload of scene's hand and object; None when there is no initial grasp (the search
    and trajectotree.cli.common.check_graspable say why). `first`: only the best `first`
    candidates (a quick lower bound: the LP over all of them takes ~1 s on the box's 2583)."""
    reach = Reachability(scene)
    mu = mu_plan(scene.config, search)
    num_fingers, stances_of = scene.num_fingers, stance_fingers(scene.num_fingers)
    if search.initial_arclengths is not None:
        arclengths = np.array([search.initial_arclengths], dtype=float)
        free = np.ones((1, num_fingers), dtype=bool)  # the search checks this grasp's stances itself
    else:
        if grasps is None:
            grasps = initial_grasp_candidates(scene, search, reach)
        if not len(grasps):
            return None
        arclengths, free = grasps.arclengths[:first], grasps.stance_mu[:first] < grasps.mu_plan
    pose = np.asarray(scene.config.initial_pose, dtype=float)
    q = np.stack([reach.closed_form_many(pose, i, arclengths[:, i]) for i in range(num_fingers)], axis=1)
    reached = np.all(np.isfinite(q), axis=(1, 2))
    if not reached.any():
        return None
    arclengths, free, q = arclengths[reached], free[reached], q[reached]
    edges, torque, moment, slack = _contact_terms(scene, pose, arclengths, q, mu)
    everyone = np.arange(num_fingers)
    hold = _heaviest(edges, torque, moment, slack, np.broadcast_to(everyone, (len(q), num_fingers)), 0.0)
    # each distinct stance once: (grasp, stance) pairs sharing the stance's contacts share the LP
    pairs = [(g, i) for g in range(len(q)) for i in range(num_fingers) if free[g, i]]
    keys = {}
    for g, i in pairs:
        keys.setdefault((i, *arclengths[g, list(stances_of[i])]), (g, i))
    stances = list(keys.values())
    switch = _heaviest(
        edges[[g for g, _ in stances]],
        torque[[g for g, _ in stances]],
        moment[[g for g, _ in stances]],
        slack[[g for g, _ in stances]],
        np.array([stances_of[i] for _, i in stances]),
        search.max_stance_force,
    )
    g = scene.config.gravity
    return Payload(
        hold_kg=float(hold.max()) / g,
        switch_kg=float(switch.max()) / g if len(switch) else 0.0,
        max_stance_force=search.max_stance_force,
        tau_max=float(max(f.tau_max.max() for f in scene.fingers)),
        grasps=len(q),
    )


def _contact_terms(scene: Scene, pose: np.ndarray, arclengths: np.ndarray, q: np.ndarray, mu: float):
    """Per grasp (G) and finger, for its two cone edges -n +- mu t (unit normal force): the
    force in W (G, 4, 2, 2: edge, xy), the joint torques J_C^T f (G, 4, 2, 2: joint, edge) and
    the moment about the object's centre (G, 4, 2); and the torque room (G, 4, 2, 2: joint,
    upper/lower), tau_max + tau_g and tau_max - tau_g (u = J_C^T f - tau_g must stay within
    +-tau_max)."""
    p_BC, n_B = scene.config.shape.points(arclengths.ravel())
    shape = (*arclengths.shape, 2)
    p_BC, n_B = p_BC.reshape(shape), n_B.reshape(shape)
    R = rotation_2d(pose[2])
    t_B = n_B @ K90.T
    edges = np.stack([-n_B + mu * t_B, -n_B - mu * t_B], axis=2) @ R.T  # (G, 4, 2, 2)
    p_WC = pose[:2] + p_BC @ R.T
    arm = p_WC - pose[:2]
    moment = arm[..., None, 0] * edges[..., 1] - arm[..., None, 1] * edges[..., 0]
    bases = np.array([f.p_W_base for f in scene.fingers])  # (4, 2)
    elbows = np.stack([f.elbow(q[:, i]) for i, f in enumerate(scene.fingers)], axis=1)  # (G, 4, 2)
    columns = np.stack([(p_WC - bases) @ K90.T, (p_WC - elbows) @ K90.T], axis=2)  # (G, 4, joint, 2)
    torque = np.einsum("gfja,gfea->gfje", columns, edges)
    tau_g = HandModel.from_scene(scene).gravity_forces(q.reshape(len(q), -1))  # (G, 4, 2)
    tau_max = np.array([f.tau_max for f in scene.fingers])  # (4, 2)
    slack = np.stack([tau_max + tau_g, tau_max - tau_g], axis=-1)
    return edges, torque, moment, slack


def _heaviest(edges, torque, moment, slack, fingers: np.ndarray, cap: float) -> np.ndarray:
    """N, the most weight each of B contact sets carries (one LP each, HeaviestLp): `fingers`
    (B, k) picks the contacts of each set from the per-grasp terms (B, 4, ...). cap > 0: sum
    lambda_n <= cap as well."""
    B, k = fingers.shape
    rows = np.arange(B)[:, None]
    F = edges[rows, fingers]  # (B, k, 2 edge, 2 xy)
    T = torque[rows, fingers]  # (B, k, 2 joint, 2 edge)
    M = moment[rows, fingers]  # (B, k, 2 edge)
    room = slack[rows, fingers]  # (B, k, 2 joint, 2 upper/lower)
    lp = HeaviestLp(k, cap)
    return np.array([lp.solve(F[b], T[b], M[b], room[b]) for b in range(B)])


class HeaviestLp:
    """maximize W over the cone-edge magnitudes x >= 0 (2k) and W >= 0: sum F_x x = 0, sum F_y x
    = W, sum moment = 0, each joint's torque within its room from above and below, and sum x <=
    cap when cap > 0 (the magnitudes' normal components are 1). Built once for k contacts; `solve`
    only updates the coefficients (Clp, in Drake: no scipy import for the CLI's quick check)."""

    def __init__(self, k: int, cap: float):
        self.k, self.cap = k, cap
        prog = MathematicalProgram()
        z = prog.NewContinuousVariables(2 * k + 1, "z")  # the magnitudes, then W
        rows = 4 * k + (1 if cap > 0 else 0)
        # column-major matrices: pydrake's dense overload (grasp.FormClosureLp says why)
        self.balance = prog.AddLinearEqualityConstraint(np.zeros((3, 2 * k + 1), order="F"), np.zeros(3), z)
        self.limits = prog.AddLinearConstraint(
            np.zeros((rows, 2 * k + 1), order="F"), np.full(rows, -np.inf), np.zeros(rows), z
        )
        prog.AddBoundingBoxConstraint(0.0, np.inf, z)
        prog.AddLinearCost(np.r_[np.zeros(2 * k), -1.0], 0.0, z)
        self.prog, self._solver, self._options = prog, ClpSolver(), SolverOptions()

    def solve(self, F: np.ndarray, T: np.ndarray, M: np.ndarray, room: np.ndarray) -> float:
        """N, W for one contact set: F (k, 2 edge, 2 xy), T (k, 2 joint, 2 edge), M (k, 2 edge),
        room (k, 2 joint, 2 upper/lower)."""
        k = self.k
        A = np.zeros((3, 2 * k + 1), order="F")
        A[0, : 2 * k], A[1, : 2 * k], A[2, : 2 * k] = F[..., 0].ravel(), F[..., 1].ravel(), M.ravel()
        A[1, -1] = -1.0
        self.balance.evaluator().UpdateCoefficients(A, np.zeros(3))
        # rows 2 (2 a + j) and 2 (2 a + j) + 1 bound joint j of contact a from above (T x <= tau_max +
        # tau_g) and below (-T x <= tau_max - tau_g); then the cap's row
        U = np.zeros((4 * k + (1 if self.cap > 0 else 0), 2 * k + 1), order="F")
        for a in range(k):
            for j in range(2):
                U[2 * (2 * a + j), 2 * a : 2 * a + 2] = T[a, j]
                U[2 * (2 * a + j) + 1, 2 * a : 2 * a + 2] = -T[a, j]
        upper = room.ravel()
        if self.cap > 0:
            U[-1, : 2 * k] = 1.0
            upper = np.r_[upper, self.cap]
        self.limits.evaluator().UpdateCoefficients(U, np.full(len(upper), -np.inf), upper)
        result = self._solver.Solve(self.prog, None, self._options)
        if not result.is_success():  # x = 0, W = 0 is feasible and W is bounded (J_C has full rank): never
            raise RuntimeError(f"payload LP failed: {result.get_solution_result()}")
        return float(result.GetSolution()[-1])
