"""Checks of the three-finger stance that holds the object while the fourth finger switches
(trajectotree.search.tree; neither is in the paper, whose search only asks that stance to be in
frictional form closure at its planned contacts).

Rolling contacts (search.rolled_stances): the plan keeps a holding finger's contact point fixed
on the object, but a fingertip sphere of radius r that sticks to a face rolls along it as the
finger's second link turns relative to the object, so s - r (a12 - theta) stays constant while it
holds (a12 the link's absolute angle, theta the object's). Executed, the contacts therefore drift
by r times the link's turn since the finger landed (goal 1.804 of seed 0: 8 mm and 4 mm after
4 s, as predicted to 0.3 mm), and a stance in closure at its planned contacts may not be at the
contacts it really has (there: needs mu 0.40 planned, 0.57 rolled). So each three-finger stance
must also be in closure at mu_plan, and search.rolled_corner_gap (2 mm) short of its face's corners,
at its rolled contacts at both ends of its transition (StanceChecks.rolled). The polygon gallery's
quadrilateral, goal -1.446: a contact planned 13.5 mm from a 56 deg corner was predicted to roll to
0.02 mm from it; in simulation it got there 0.8 s early (1-1.4 mm beyond the prediction, most of
it from where the sphere landed), pivoted over the corner, and the object dropped. A segment in
which no finger switches is checked the same way, all fingers holding. The rolling depends on
when each finger landed (the node's path); the search still merges states by their contacts, so
a state first reached by a worse history can hide a plan another would allow (incomplete, never
unsafe).

Holding force (search.max_stance_force): closure says the stance can resist any wrench, not at
what cost. Some three-finger stances on polygons (two fingers nearly antipodal, the third barely
pushing against gravity) carry the object's weight only through large squeezing forces: at the
planned contacts, the least total normal force that balances the weight at mu_plan was 12-83 N for
the CITO segments on the polygon gallery that failed, <= 7.3 N for every segment that converged
first time (the object weighs 0.49 N). The hand's joints give at most 1 N m, so those segments
saturate torque and a pinned fingertip drifts (~1 mm), failing the physics check. The search
therefore refuses a switch whose stance needs more than search.max_stance_force at either end of
its transition (StanceChecks.too_heavy, the LP of HoldingForceLp).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.solvers import ClpSolver, MathematicalProgram, SolverOptions

from trajectotree.geometry import ConvexPolygon, rotation_2d
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.scene.kinematics import jacobian_from_links
from trajectotree.scene.plant import Scene
from trajectotree.scene.statics import cone_rows, grasp_matrix_W, perp, pyramid_edges, torque_rows
from trajectotree.search.grasp import WRENCH_DIM, closure_edges_parts, in_closure_many
from trajectotree.search.initial_grasp import stance_fingers
from trajectotree.search.reach import Reachability


def arclength_key(perimeter: float, s: float) -> float:
    """The canonical arclength key: in [0, perimeter), rounded to 1e-9 m."""
    return round(float(s) % perimeter, 9)


class HoldingForceLp:
    """The least total normal force of k contacts that balances a wrench w on the object:

        minimize sum x  s.t.  E x = w,  x >= 0,

    x the magnitudes along the 2k cone edges -n +- mu t (each of unit normal component, so
    sum x = sum lambda_n) and E their wrenches about the object's origin (its centroid). Built
    once; `solve` only updates E and w (UpdateCoefficients), like grasp.FormClosureLp."""

    def __init__(self, num_contacts: int):
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(2 * num_contacts, "x")
        self.balance = prog.AddLinearEqualityConstraint(  # column-major: see grasp.FormClosureLp
            np.zeros((WRENCH_DIM, 2 * num_contacts), order="F"), np.zeros(WRENCH_DIM), x
        )
        prog.AddBoundingBoxConstraint(0.0, np.inf, x)
        prog.AddLinearCost(np.ones(2 * num_contacts), 0.0, x)
        self.prog, self.lp_calls = prog, 0
        self._solver, self._options = ClpSolver(), SolverOptions()

    def solve(self, p_BC, n_B, mu: float, w_B) -> float:
        """N, the least sum of normal forces of contacts (p_BC, n_B) (k, 2) at friction mu
        whose net wrench on the object is w_B (3,); inf when no such forces exist."""
        A, B = closure_edges_parts(p_BC, n_B)
        E = np.concatenate([A + mu * B, A - mu * B], axis=0).T  # (3, 2k) wrenches of the cone edges
        self.balance.evaluator().UpdateCoefficients(E, np.asarray(w_B, dtype=float))
        self.lp_calls += 1
        result = self._solver.Solve(self.prog, None, self._options)
        return float(result.get_optimal_cost()) if result.is_success() else np.inf


PUSH_DIRECTIONS = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))  # the pushes push_capacity resists, in W


class PushCapacityLp:
    """The hardest push P = t u (u a unit direction in W) that k holding fingers resist while
    they also hold the object's weight, each within a normal-force bound and its joints'
    torque limits:

        maximize t  s.t.  G lambda = w_hold - t (u, 0),  |lambda_t| <= mu lambda_n,
                          0 <= lambda_n <= f_max,  tau_lower <= A lambda <= tau_upper,

    lambda = (lambda_n, lambda_t) per finger, G their grasp matrix in W about the object's
    centroid, w_hold the weight's opposite, and A, tau_lower, tau_upper the joint torques of
    the contact forces beside gravity on the links (statics.torque_rows). It is the static
    limit of any controller that keeps the stance: a harder push moves the object for as
    long as it lasts. Built once; `solve` only updates the coefficients (like HoldingForceLp)."""

    def __init__(self, num_contacts: int, mu: float, max_normal_force: float):
        n = 2 * num_contacts
        prog = MathematicalProgram()
        z = prog.NewContinuousVariables(n + 1, "z")  # finger-major (lambda_n, lambda_t), then t
        self.balance = prog.AddLinearEqualityConstraint(np.zeros((3, n + 1), order="F"), np.zeros(3), z)
        cone = np.asfortranarray(np.hstack([cone_rows(mu, num_contacts), np.zeros((n, 1))]))
        prog.AddLinearConstraint(cone, np.full(n, -np.inf), np.zeros(n), z)
        self.torque = prog.AddLinearConstraint(np.zeros((n, n + 1), order="F"), np.zeros(n), np.zeros(n), z)
        lower = np.tile([0.0, -np.inf], num_contacts)
        upper = np.tile([max_normal_force, np.inf], num_contacts)
        prog.AddBoundingBoxConstraint(np.append(lower, -np.inf), np.append(upper, np.inf), z)
        prog.AddLinearCost(np.append(np.zeros(n), -1.0), 0.0, z)
        self.prog, self.lp_calls = prog, 0
        self._solver, self._options = ClpSolver(), SolverOptions()

    def solve(self, G, torque, w_hold, u) -> float:
        """N, the hardest push along u (2,) in W resisted with the grasp matrix G (3, 2k),
        `torque` = (A, lower, upper) from statics.torque_rows and the holding wrench w_hold (3,);
        -inf when the fingers cannot even hold the weight."""
        A, lower, upper = torque
        # column-major, as the other LPs of the search (grasp.FormClosureLp says why)
        self.balance.evaluator().UpdateCoefficients(np.asfortranarray(np.column_stack([G, [u[0], u[1], 0.0]])), w_hold)
        self.torque.evaluator().UpdateCoefficients(
            np.asfortranarray(np.column_stack([A, np.zeros(len(A))])), lower, upper
        )
        self.lp_calls += 1
        result = self._solver.Solve(self.prog, None, self._options)
        return float(-result.get_optimal_cost()) if result.is_success() else -np.inf


def weight_support_B(theta: float, weight: float) -> np.ndarray:
    """(3,) the wrench the fingers must apply to hold the object still at orientation theta:
    the weight's opposite R(theta)^T (0, m g) in B, no moment about the centroid."""
    return np.array([np.sin(theta) * weight, np.cos(theta) * weight, 0.0])


def landed_depths(node, fingers) -> dict[int, int]:
    """{finger: the depth of the node where it landed on its contact} for `fingers` of a search node (the
    last on its path that it switched to, 0 when it never switched)."""
    out, step = {}, node
    while step is not None and len(out) < len(fingers):
        if step.switching_finger in fingers and step.switching_finger not in out:
            out[step.switching_finger] = step.depth
        step = step.parent
    return {j: out.get(j, 0) for j in fingers}


class StanceChecks:
    """The rolled-stance and holding-force checks of one search (one object path)."""

    def __init__(
        self,
        scene: Scene,
        reach: Reachability,
        poses: np.ndarray,
        mu_plan: float,
        max_force: float,
        angles: Callable[[int, int, float], np.ndarray] | None = None,
        corner_gap: float = 0.0,
        push_normal_force: float = 8.0,
    ):
        """`angles(depth, finger, s)`: a finger's closed-form joint angles at node `depth` with its
        contact at arclength s (a table of them; None: Reachability.closed_form); `corner_gap` (m,
        search.rolled_corner_gap): how far short of a corner rolled contacts stay;
        `push_normal_force` (N, search.push_normal_force): each finger's bound in push_capacity."""
        self.scene, self.reach, self.poses, self.mu_plan = scene, reach, poses, mu_plan
        self.push_lps = {
            k: PushCapacityLp(k, mu_plan, push_normal_force) for k in (scene.num_fingers - 1, scene.num_fingers)
        }
        self._push: dict[tuple, float] = {}  # (depth, ((finger, arclength), ...), direction) -> N
        self._push_rows: dict[tuple, tuple] = {}  # (depth, ((finger, arclength), ...)) -> push_rows'
        self.corner_gap = corner_gap
        self.table = angles
        self.boundary: ConvexPolygon = scene.config.shape
        self.max_force = max_force  # N, 0: no cap
        self.weight = scene.config.box_mass * scene.config.gravity  # N
        self.stances = stance_fingers(scene.num_fingers)  # the holders while finger i switches
        self.lp = HoldingForceLp(scene.num_fingers - 1)
        self._force: dict[tuple, float] = {}  # (depth, stance arclengths) -> N
        self._rolled: dict[tuple, tuple[list[float], bool]] = {}  # rolled_row's
        self._rolled_closed: dict[tuple, bool] = {}  # the same rows -> their rolled contacts in closure at mu_plan

    # -- rolling contacts ---------------------------------------------------------------------
    def rolled(self, node, depth: int, finger: int | None) -> Refusal | None:
        """Why the stance holding the object while `finger` (None: no finger, all hold) moves from
        `node` to the child at `depth` fails at its rolled contacts (None when it holds): at node.depth and at `depth`,
        every contact still on its face (the rolling law holds along one face) and `corner_gap`
        short of the corners that end it (a sphere that rolls onto a corner pivots over it and its
        normal turns by the corner's angle), and the three in frictional form closure at mu_plan
        (grasp.in_closure_many, the exact test behind required_mu; the LP's 1e-3 N margin is not
        applied here)."""
        stance = tuple(range(self.scene.num_fingers)) if finger is None else self.stances[finger]
        landed = landed_depths(node, stance)
        held = tuple((j, node.arclengths[j], landed[j]) for j in stance)
        rows = [(d, held) for d in (node.depth, depth)]
        if any(self.rolled_row(row)[1] for row in rows):
            return Refusal(RefusalKind.STANCE_ROLLS_OFF, stance=stance, limit=self.corner_gap)
        missing = [row for row in rows if row not in self._rolled_closed]
        if missing:  # both rows in one stack when neither is known
            p_BC, n_B = self.boundary.points(np.ravel([self.rolled_row(row)[0] for row in missing]))
            A, B = closure_edges_parts(
                p_BC.reshape(len(missing), len(stance), 2), n_B.reshape(len(missing), len(stance), 2)
            )
            self._rolled_closed.update(zip(missing, in_closure_many(A, B, self.mu_plan).tolist()))
        if not all(self._rolled_closed[row] for row in rows):
            return Refusal(RefusalKind.STANCE_ROLLED_OPEN, stance=stance, mu_plan=self.mu_plan)
        return None

    def rolled_row(self, row: tuple) -> tuple[list[float], bool]:
        """(the rolled contacts, whether one leaves its face or comes within corner_gap of a corner that
        ends it) of a stance `row` = (depth, ((finger, arclength, depth it landed at), ...)), memoized:
        stances reached by different paths share it (a third of the search's rows)."""
        if row not in self._rolled:
            depth, held = row
            r, perimeter = self.reach.tip_radius, self.boundary.perimeter
            rolled = [
                arclength_key(perimeter, s + r * (self.link_turn(depth, j, s) - self.link_turn(landed, j, s)))
                for j, s, landed in held
            ]
            off = np.any(self.boundary.sides(rolled) != self.boundary.sides([s for _, s, _ in held])) or not np.all(
                self.boundary.clear_of_sides_ends(rolled, self.corner_gap)
            )
            self._rolled[row] = (rolled, bool(off))
        return self._rolled[row]

    def link_turn(self, depth: int, finger: int, s: float) -> float:
        """Angle of `finger`'s second link relative to the object at node `depth` with its
        contact at arclength s (closed-form IK; the node's Drake IK agrees)."""
        q = self.joint_angles(depth, finger, s)
        return float(self.scene.fingers[finger].psi + q[0] + q[1] - self.poses[depth][2])

    def joint_angles(self, depth: int, finger: int, s: float) -> np.ndarray:
        """(2,) `finger`'s closed-form joint angles at node `depth` with its contact at arclength s."""
        return (
            self.reach.closed_form(self.poses[depth], finger, s).q
            if self.table is None
            else self.table(depth, finger, s)
        )

    # -- push capacity ------------------------------------------------------------------------
    def push_capacity(self, node, depth: int, finger: int | None) -> float:
        """N, the hardest push along +-x and +-y in W that the stance holding the object while
        `finger` (None: none, all hold) moves from `node` to the child at `depth` resists at both
        ends of its transition, at its planned contacts (PushCapacityLp at mu_plan)."""
        return min(self.push_values(node, depth, finger))

    def push_values(self, node, depth: int, finger: int | None):
        """push_capacity's LP values (N), one per end of the transition and direction of PUSH_DIRECTIONS,
        each solved as it is iterated (memoized): their least is push_capacity, and a caller that needs
        only to know that it is below some value may stop early (trajectotree.search.tree's push order)."""
        stance = tuple(range(self.scene.num_fingers)) if finger is None else self.stances[finger]
        held = tuple((j, node.arclengths[j]) for j in stance)
        for d in (node.depth, depth):
            for n in range(len(PUSH_DIRECTIONS)):
                yield self.push_along(held, d, n)

    def push_along(self, held: tuple[tuple[int, float], ...], depth: int, direction: int) -> float:
        """N, the hardest push along PUSH_DIRECTIONS[direction] that fingers `held` ((finger, arclength), ...)
        resist at pose x*_depth; memoized."""
        key = (depth, held, direction)
        if key not in self._push:
            G, torque, w_hold = self.push_rows(held, depth)
            self._push[key] = self.push_lps[len(held)].solve(G, torque, w_hold, PUSH_DIRECTIONS[direction])
        return self._push[key]

    def push_rows(self, held: tuple[tuple[int, float], ...], depth: int) -> tuple:
        """(G, (A, lower, upper), w_hold): PushCapacityLp's coefficients for fingers `held` at pose x*_depth
        (its arguments but the direction); memoized."""
        key = (depth, held)
        if key not in self._push_rows:
            fingers = [j for j, _ in held]
            R = rotation_2d(self.poses[depth][2])
            p_BC, n_B = self.boundary.points(np.array([s for _, s in held]))
            n_W = n_B @ R.T
            q = np.array([self.joint_angles(depth, j, s) for j, s in held])
            J_WF = np.array([jacobian_from_links(*self.scene.fingers[j].links(qj)) for j, qj in zip(fingers, q)])
            gravity = np.array(
                [self.scene.fingers[j].gravity_torques(qj, self.scene.config.gravity) for j, qj in zip(fingers, q)]
            )
            tau_max = np.array([self.scene.fingers[j].tau_max for j in fingers])
            A, lower, upper, _ = torque_rows(J_WF, n_W, perp(n_W), self.reach.tip_radius, gravity, tau_max)
            G = grasp_matrix_W(p_BC @ R.T, n_W)
            self._push_rows[key] = (G, (A, lower, upper), np.array([0.0, self.weight, 0.0]))
        return self._push_rows[key]

    # -- holding force ------------------------------------------------------------------------
    def too_heavy(self, node, depth: int, finger: int) -> Refusal | None:
        """Why the stance holding the object while `finger` moves from `node` to the child at
        `depth` is refused for its force (None when it is not, or when there is no cap): it needs
        more than max_force N in total, at its planned contacts (where CITO pins the fingertips),
        to carry the object's weight at node.depth or at `depth`."""
        if not self.max_force:
            return None
        stance = self.stances[finger]
        planned = tuple(node.arclengths[j] for j in stance)
        if any(self.holding_force(planned, d) > self.max_force for d in (node.depth, depth)):
            return Refusal(RefusalKind.STANCE_TOO_HEAVY, stance=stance, mu_plan=self.mu_plan, limit=self.max_force)
        return None

    def holding_force(self, arclengths: tuple[float, ...], depth: int) -> float:
        """N, the least total normal force of contacts `arclengths` (friction mu_plan) that holds
        the object still against gravity at pose x*_depth (HoldingForceLp); memoized."""
        key = (depth, arclengths)
        if key not in self._force:
            p_BC, n_B = self.boundary.points(np.array(arclengths))
            self._force[key] = self.lp.solve(
                p_BC, n_B, self.mu_plan, weight_support_B(self.poses[depth][2], self.weight)
            )
        return self._force[key]


# -- in space ------------------------------------------------------------------------------------
class SpatialHoldingLp:
    """The smallest largest joint torque with which k fingers hold the object still in space:

        minimize t  s.t.  W x = w_hold,  x >= 0,  -t <= tau_g + A x <= t,

    x the magnitudes along each contact's m pyramid edges (statics.pyramid_edges), W (6, k m) their
    wrenches about the object's centre (W frame), w_hold the weight's opposite (0, 0, m g, 0, 0, 0)
    for an object whose centre of mass is its centre, tau_g (k n,) the joints' torques against the
    fingers' own weight and A (k n, k m) the joint torques of the edge forces (J_WC^T per finger,
    statics.finger_torques). The stance holds within the motors iff t* <= tau_max. Built once;
    `solve` only updates the coefficients."""

    def __init__(self, num_contacts: int, num_edges: int, joints_per_finger: int):
        n, r = num_contacts * num_edges, num_contacts * joints_per_finger
        prog = MathematicalProgram()
        z = prog.NewContinuousVariables(n + 1, "z")  # edge magnitudes, then t
        self.balance = prog.AddLinearEqualityConstraint(np.zeros((6, n), order="F"), np.zeros(6), z[:n])
        self.upper = prog.AddLinearConstraint(np.zeros((r, n + 1), order="F"), np.full(r, -np.inf), np.zeros(r), z)
        self.lower = prog.AddLinearConstraint(np.zeros((r, n + 1), order="F"), np.full(r, -np.inf), np.zeros(r), z)
        prog.AddBoundingBoxConstraint(0.0, np.inf, z)
        prog.AddLinearCost(np.append(np.zeros(n), 1.0), 0.0, z)
        self.prog, self._z, self.lp_calls = prog, z, 0
        self._solver, self._options = ClpSolver(), SolverOptions()

    def solve(self, W, A, tau_gravity, w_hold) -> tuple[float, np.ndarray]:
        """(t* N m, the edge magnitudes x (k m,)); (inf, zeros) when no forces hold the object."""
        ones = np.ones((len(A), 1))
        tau_g = np.ravel(tau_gravity)
        self.balance.evaluator().UpdateCoefficients(np.asfortranarray(W), np.asarray(w_hold, dtype=float))
        # tau_g + A x <= t  and  -(tau_g + A x) <= t
        self.upper.evaluator().UpdateCoefficients(
            np.asfortranarray(np.hstack([A, -ones])), np.full(len(A), -np.inf), -tau_g
        )
        self.lower.evaluator().UpdateCoefficients(
            np.asfortranarray(np.hstack([-A, -ones])), np.full(len(A), -np.inf), tau_g
        )
        self.lp_calls += 1
        result = self._solver.Solve(self.prog, None, self._options)
        if not result.is_success():
            return np.inf, np.zeros(W.shape[1])
        return float(result.get_optimal_cost()), result.GetSolution(self._z[:-1])


def spatial_torque_rows(J_WC, n_W, mu: float, num_edges: int) -> np.ndarray:
    """(k n, k m): the joint torques of unit magnitudes along each contact's pyramid edges, block-
    diagonal (a finger's contact moves only its joints): J_WC (k, 3, n) at the contact points."""
    edges = pyramid_edges(n_W, mu, num_edges)  # (k, m, 3)
    k, n = len(J_WC), J_WC.shape[2]
    A = np.zeros((k * n, k * num_edges))
    for i in range(k):
        A[i * n : (i + 1) * n, i * num_edges : (i + 1) * num_edges] = J_WC[i].T @ edges[i].T
    return A


SPATIAL_PUSH_DIRECTIONS = tuple(  # the pushes spatial push capacity resists: forces along +-x, +-y, +-z in W
    tuple(s * e for e in row) for row in np.eye(3).tolist() for s in (1.0, -1.0)
)


class SpatialPushLp:
    """The hardest push P = s u (u a unit wrench direction in W: a force, or a torque about the
    centre) that k fingers resist while they hold the object, each within a normal-force bound and
    its joints' torque limits:

        maximize s  s.t.  W x = w_hold - s u,  x >= 0,  sum of each contact's x <= f_max,
                          -tau_max <= tau_g + A x <= tau_max.

    Each edge has unit normal component, so a contact's sum of x is its normal force. The static
    limit of any controller that keeps the stance, as the planar PushCapacityLp. Built once."""

    def __init__(self, num_contacts: int, num_edges: int, joints_per_finger: int, max_normal_force: float):
        n, r = num_contacts * num_edges, num_contacts * joints_per_finger
        prog = MathematicalProgram()
        z = prog.NewContinuousVariables(n + 1, "z")  # edge magnitudes, then s
        self.balance = prog.AddLinearEqualityConstraint(np.zeros((6, n + 1), order="F"), np.zeros(6), z)
        self.torque = prog.AddLinearConstraint(np.zeros((r, n + 1), order="F"), np.zeros(r), np.zeros(r), z)
        normal = np.kron(np.eye(num_contacts), np.ones((1, num_edges)))
        prog.AddLinearConstraint(
            np.asfortranarray(np.hstack([normal, np.zeros((num_contacts, 1))])),
            np.zeros(num_contacts),
            np.full(num_contacts, max_normal_force),
            z,
        )
        prog.AddBoundingBoxConstraint(np.append(np.zeros(n), -np.inf), np.full(n + 1, np.inf), z)
        prog.AddLinearCost(np.append(np.zeros(n), -1.0), 0.0, z)
        self.prog, self.lp_calls = prog, 0
        self._solver, self._options = ClpSolver(), SolverOptions()

    def solve(self, W, A, tau_gravity, tau_max, w_hold, u) -> float:
        """N (or N m), the hardest push along the unit wrench u (6,); -inf when the fingers cannot even hold."""
        tau_g, tau_max = np.ravel(tau_gravity), np.ravel(tau_max)
        self.balance.evaluator().UpdateCoefficients(np.asfortranarray(np.column_stack([W, u])), np.asarray(w_hold))
        self.torque.evaluator().UpdateCoefficients(
            np.asfortranarray(np.column_stack([A, np.zeros(len(A))])), -tau_max - tau_g, tau_max - tau_g
        )
        self.lp_calls += 1
        result = self._solver.Solve(self.prog, None, self._options)
        return float(-result.get_optimal_cost()) if result.is_success() else -np.inf


def spatial_push_capacity(lp: SpatialPushLp, W, A, tau_gravity, tau_max, w_hold) -> float:
    """N, the least over SPATIAL_PUSH_DIRECTIONS of the hardest push the stance resists."""
    return min(lp.solve(W, A, tau_gravity, tau_max, w_hold, np.r_[u, 0.0, 0.0, 0.0]) for u in SPATIAL_PUSH_DIRECTIONS)
