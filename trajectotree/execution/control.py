"""The object-level grasp controller (the default executor's; the paper's eq. 20 is
trajectotree.execution.impedance), open loop (`GraspController`) or fed by the closed loop
(`ClosedLoopGraspController`, trajectotree.execution.closed_loop and .reflexes).

GraspController, periodic at ControllerGains.rate_hz, reads the measured state of
the box and the hand (the plant's; there is no estimator) and
  1. asks for the box wrench w = M (a_ref + Kp (X_ref - X) + Kd (V_ref - V)) + gravity
     (M the planned mass and inertia, X_ref a cubic Hermite through the plan);
  2. splits it into forces of the fingers in contact with a QP (OSQP, built once):
     min wrench_weight |G lambda - w|^2 + |lambda - lambda_plan|^2 with
     lambda_n in s [min, max] N and |lambda_t| <= mu lambda_n, where the force budget s
     of a switching finger ramps to 0 after lift-off and back before landing;
  3. commands tau = J^T ((1 - s) K_t (p_target - p) + D (v_target - v)) + J_C^T f + g_hand,
     with fingertip targets the planned box-frame fingertip positions mapped through the
     MEASURED box pose (a switching finger follows its box-frame path, lifted): a finger
     in contact is force-controlled, a free one position-controlled;
  4. with gains.grasp.hand_dynamics, also M(q) J^+ (a_target - Jdot qdot) + Coriolis + joint damping, the torques
     that move the links themselves (a touching finger with its box point, a swinging one along its path).
Soft fingertip springs with strong object gains: stiff springs anchored to the
measured box inject tangential force as the spheres roll and lose the grasp.

Both controllers are one control law on `Estimates` (the open loop's are the plan's friction and mass,
no reflex and no disturbance, fixed) and on the schedule sample each finger follows (the open loop's:
the plan's, for all); they differ only where the grasp forces are allocated (`grasp_forces`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram, OsqpSolver, SolverOptions
from pydrake.systems.framework import EventStatus, LeafSystem

from trajectotree.config import ControllerGains
from trajectotree.execution.fingers import HandKinematics, check_finger_major
from trajectotree.execution.in_effect import declare_plan_input
from trajectotree.execution.reference import GraspSchedule
from trajectotree.geometry import rotation_2d, wrap_angle
from trajectotree.scene.plant import Scene
from trajectotree.scene.statics import cone_rows, grasp_matrix_W, perp, torque_rows

ACCEL_LIMIT = np.array([0.0, 0.0, 5.0])  # m/s^2, m/s^2, rad/s^2: the box feedback the fingers' own inertia follows
SINGULAR_DAMPING = 0.01  # m, of the fingers' damped least-squares accelerations (a tenth of Drake's gripper's links)


class GraspForceQp:
    """min wrench_weight |G lambda - w|^2_W + |lambda - lambda_plan|^2 over lambda = (lambda_n,
    lambda_t) of the `num_fingers` fingers, lambda_n in [lo, hi], |lambda_t| <= mu lambda_n. Built once;
    each solve updates the cost and the bounds (OSQP). With `torque_rows` (the closed loop)
    it also has 2 rows per finger that bound the joint torques lambda makes (`solve`'s
    `torque`), and is solved by Clarabel: OSQP's ADMM needed a median of 825 iterations on those
    rows and ended inaccurate or at its 4000-iteration limit on 42 of 5651 solves of one run."""

    def __init__(
        self, mu: float, torque_length: float, wrench_weight: float, *, num_fingers: int, torque_rows: bool = False
    ):
        n = 2 * num_fingers
        self._num_fingers = num_fingers
        self._prog = MathematicalProgram()
        self._z = self._prog.NewContinuousVariables(n, "lambda")  # finger-major (n, t)
        self._cost = self._prog.AddQuadraticCost(np.eye(n), np.zeros(n), self._z, is_convex=True)
        self._bounds = self._prog.AddBoundingBoxConstraint(np.zeros(n), np.zeros(n), self._z)
        self._cone = self._prog.AddLinearConstraint(
            cone_rows(mu, num_fingers), np.full(n, -np.inf), np.zeros(n), self._z
        )
        self._torque = None
        if torque_rows:
            unbounded = np.full(n, np.inf)
            self._torque = self._prog.AddLinearConstraint(np.eye(n), -unbounded, unbounded, self._z)
        self._mu = mu
        self._identity = np.eye(n)
        self._W = wrench_weight * np.diag([1.0, 1.0, 1.0 / torque_length**2])
        self._options = SolverOptions()
        if torque_rows:
            self._solver = ClarabelSolver()
        else:
            self._solver = OsqpSolver()
            for name, value in (("eps_abs", 1e-6), ("eps_rel", 1e-6), ("polishing", 0), ("verbose", 0)):
                self._options.SetOption(OsqpSolver.id(), name, value)

    def set_friction(self, mu: float) -> None:
        """The cones' friction coefficient from the next solve on."""
        if mu != self._mu:
            n = 2 * self._num_fingers
            self._cone.evaluator().UpdateCoefficients(
                cone_rows(mu, self._num_fingers), np.full(n, -np.inf), np.zeros(n)
            )
            self._mu = mu

    def solve(self, G, wrench, lambda_plan, lo, hi, torque=None, torque_weight: float = 1.0) -> np.ndarray:
        """lambda (F, 2) for the grasp matrix G (3, 2F), the wrench w (3,), the plan's
        lambda (F, 2) and the normal-force bounds lo, hi (F,); `torque` (A (2F, 2F), lower (2F,),
        upper (2F,)): lower <= A lambda <= upper (a QP built with torque_rows); `torque_weight`
        multiplies the weight of the torque residual. Falls back to
        the plan's forces, clipped to the bounds, if the solver fails."""
        z_plan = lambda_plan.ravel()
        GtW = G.T @ (self._W * [1.0, 1.0, torque_weight])  # W diagonal: its torque column scaled
        self._cost.evaluator().UpdateCoefficients(
            2.0 * (GtW @ G + self._identity), -2.0 * (GtW @ wrench + z_plan), 0.0, True
        )
        t_max = self._mu * hi
        self._bounds.evaluator().set_bounds(np.column_stack([lo, -t_max]).ravel(), np.column_stack([hi, t_max]).ravel())
        if torque is not None:
            self._torque.evaluator().UpdateCoefficients(*torque)
        result = self._solver.Solve(self._prog, None, self._options)
        if not result.is_success():
            n = np.clip(lambda_plan[:, 0], lo, hi)
            return np.column_stack([n, np.clip(lambda_plan[:, 1], -self._mu * n, self._mu * n)])
        return result.get_x_val().reshape(self._num_fingers, 2)  # z is the program's only variable


@dataclass(frozen=True)
class Estimates:
    """What the controller assumes of the world: the closed loop's estimates
    (trajectotree.execution.closed_loop), or the plan's values in open loop (`planned`)."""

    mu: float  # the friction coefficient of the QP's cones (closed loop: the estimate, ConeFriction's lag)
    mass: float  # kg, the box mass estimate (the desired wrench's gravity and inertia)
    reflex: float  # 0..1, the push reflex (squeeze and object gains raised in proportion)
    # (2,) N in W, the force on the box that its contacts and gravity do not explain (the desired wrench cancels it)
    disturbance: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @classmethod
    def planned(cls, mu: float, mass: float) -> Estimates:
        """The plan's friction and mass, no push."""
        return cls(mu=mu, mass=mass, reflex=0.0)


@dataclass(frozen=True)
class EstimatePorts:
    """The input ports through which a closed-loop controller (planar or in space) reads the closed loop's estimates:
    `friction` (1, the friction its cones follow), `mass_estimate` (1, kg), `reflex` (1, 0..1), `disturbance` (N in W:
    2 in the plane, 3 in space)."""

    friction: object  # InputPort
    mass: object
    reflex: object
    disturbance: object

    @classmethod
    def declare(cls, system: LeafSystem, disturbance_size: int) -> EstimatePorts:
        """Declares the four ports on `system`, in this order."""
        return cls(
            system.DeclareVectorInputPort("friction", 1),
            system.DeclareVectorInputPort("mass_estimate", 1),
            system.DeclareVectorInputPort("reflex", 1),
            system.DeclareVectorInputPort("disturbance", disturbance_size),
        )

    def read(self, context) -> Estimates:
        return Estimates(
            mu=float(self.friction.Eval(context)[0]),
            mass=float(self.mass.Eval(context)[0]),
            reflex=float(self.reflex.Eval(context)[0]),
            disturbance=np.array(self.disturbance.Eval(context)),
        )


class GraspController(LeafSystem):
    """Object-level grasp control of a planned box motion, open loop (see the module doc).
    Input ports: `box_state` (6: x, y, theta and their rates, in W, the box's planar
    joint), `hand_state` (4F for F fingers: the hand's [q; v]) and `plan` (the PlanInEffect whose
    schedule it follows: trajectotree.execution.in_effect). Output port:
    `actuation` (2F, N m, the plant's actuation order), updated every 1 / gains.rate_hz s and held
    in between. `mass` is the plan's and `mu` the friction its QP's cones allow
    (simulate passes max(search, controller friction_safety) x scene.mu), not the simulated plant's."""

    TORQUE_ROWS = False  # the QP bounds the joint torques its forces make (GraspForceQp)

    def __init__(self, scene: Scene, gains: ControllerGains, *, mu: float):
        super().__init__()
        c = scene.config
        self.gains = gains
        self._kinematics, self._tip_radius = HandKinematics(scene.fingers, c.gravity), scene.tip_radius
        self._gravity = c.gravity
        self._shape = c.shape
        self._scene_config = c
        self.planned = Estimates.planned(mu, c.box_mass)
        self._friction_safety = mu / c.mu
        self._tau_max = np.array([f.tau_max for f in scene.fingers])  # (F, 2) N m
        check_finger_major(scene)
        self._num_fingers, self._num_joints = scene.num_fingers, scene.num_hand_joints
        # m, the torque length of the wrench QP: the circumradius (the box's half diagonal)
        self._qp = GraspForceQp(
            mu,
            c.shape.circumradius,
            gains.grasp.wrench_weight,
            num_fingers=scene.num_fingers,
            torque_rows=self.TORQUE_ROWS,
        )
        B = scene.plant.MakeActuationMatrix()  # (nv, nu), a selection
        self._u_from_tau = B[scene.hand_v_indices].T  # hand-joint torques -> actuation
        self.box_state_port = self.DeclareVectorInputPort("box_state", 6)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * scene.num_hand_joints)
        self.plan_port = declare_plan_input(self)
        state = self.DeclareDiscreteState(B.shape[1])
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self.UpdateActuation)
        self.DeclareInitializationDiscreteUpdateEvent(self.UpdateActuation)
        self.actuation_port = self.DeclareStateOutputPort("actuation", state)

    def estimates(self, context) -> Estimates:
        """What the controller assumes now: the plan's values."""
        return self.planned

    def clocks(self, context, schedule: GraspSchedule) -> np.ndarray:
        """(F,) int, the sample of `schedule` each finger follows now: the plan's."""
        return np.full(self._num_fingers, schedule.index(context.get_time()))

    def UpdateActuation(self, context, discrete_state):
        box_state, hand_state = self.box_state_port.Eval(context), self.hand_state_port.Eval(context)
        s = self.plan_port.Eval(context).schedule
        discrete_state.set_value(
            self.compute_actuation(
                s, context.get_time(), box_state, hand_state, self.estimates(context), self.clocks(context, s)
            )
        )
        return EventStatus.Succeeded()

    def desired_acceleration(self, s: GraspSchedule, n: int, box_state, estimates: Estimates) -> np.ndarray:
        """(3,) the box's desired acceleration at sample n of `s`: the plan's, with pose and velocity feedback
        (the push reflex raises the gains; kd grows with the square root of kp: the same damping ratio,
        a faster response)."""
        g = self.gains
        error = s.X[n] - box_state[:3]
        error[2] = wrap_angle(error[2])
        boost = 1.0 + estimates.reflex * (g.push_reflex.gain - 1.0)
        kp, kd = boost * g.grasp.object_kp, np.sqrt(boost) * g.grasp.object_kd
        return s.A[n] + kp * error + kd * (s.V[n] - box_state[3:])

    def desired_wrench(self, s: GraspSchedule, n: int, box_state, estimates: Estimates) -> np.ndarray:
        """(f_x N, f_y N, torque N m) the fingers should apply to the box at sample n of `s`, cancelling the
        disturbance."""
        mass, inertia = estimates.mass, self._scene_config.inertia_zz(estimates.mass)
        a = self.desired_acceleration(s, n, box_state, estimates)
        wrench = np.array([mass * a[0], mass * (a[1] + self._gravity), inertia * a[2]])
        wrench[:2] -= self.gains.push_reflex.disturbance_feedforward * estimates.disturbance
        return wrench

    def finger_forces(
        self, s: GraspSchedule, n: int, box_state, p_WF, estimates: Estimates, joints=None, *, at=None, scale=None
    ) -> tuple[np.ndarray, np.ndarray]:
        """f_W (F, 2), the force each finger should apply to the box at sample n of `s` (QP),
        and n_W (F, 2), the outward normals of the faces it pushes on. The forces act
        where the measured fingertips p_WF (F, 2) touch the faces: a sphere rolls along
        the face as the box turns, and with the planned points instead, 2 mm of rolling
        under 1 N grips left a slow in-grasp turn 0.03 rad behind. The normals too are
        the object's at those points (the box's: its faces'), not the planned contacts':
        on a disc, spheres that rolled 15-30 deg around it from their planned contacts
        left the planned normals that far off, the QP credited the squeeze with a torque
        a disc's normals cannot make, squeezed to 3 N and let go (4 of 12 disc goals
        dropped). `joints` = (J_WF (F, 2, 2), the other joint torques (F, 2)), which a
        closed-loop controller's QP bounds."""
        R = rotation_2d(box_state[2])
        p_BF = (p_WF - box_state[:2]) @ R  # R^T (p_WF - p): the measured fingertips in B
        n_W = self._shape.face_normals(self._shape.nearest_points(p_BF)) @ R.T
        t_W = perp(n_W)
        r_W = p_WF - self._tip_radius * n_W - box_state[:2]  # contact points, from the box origin
        G = grasp_matrix_W(r_W, n_W)
        at = (n, slice(None)) if at is None else at  # each finger's sample (all n but a finger landing early)
        scale = s.force_scale[at] if scale is None else scale
        wrench = self.desired_wrench(s, n, box_state, estimates)
        lam = self.grasp_forces(G, wrench, s.lambda_plan[at], scale, estimates, (n_W, t_W), joints)
        return -lam[:, :1] * n_W + lam[:, 1:] * t_W, n_W

    def grasp_forces(self, G, wrench, lambda_plan, scale, estimates: Estimates, normals, joints) -> np.ndarray:
        """lambda (F, 2), the fingers' (normal, tangential) forces that make `wrench` (GraspForceQp) within
        their force budgets `scale` (F,), at the friction the QP was built with."""
        g = self.gains
        return self._qp.solve(
            G, wrench, lambda_plan, scale * g.grasp.min_normal_force, scale * g.grasp.max_normal_force
        )

    def compute_actuation(
        self, s: GraspSchedule, t: float, box_state, hand_state, estimates: Estimates, clocks
    ) -> np.ndarray:
        """The actuation at time t following the schedule `s`; `clocks` (F,) the sample of `s` each finger
        follows (the landing reflex's, trajectotree.execution.reflexes; the plan's sample for all in open loop)."""
        g = self.gains
        n = s.index(t)
        q, v = hand_state[: self._num_joints], hand_state[self._num_joints :]
        p_WF, J_WF, g_hand = self._kinematics(q)
        v_WF = np.einsum("fij,fj->fi", J_WF, v.reshape(self._num_fingers, 2))
        R = rotation_2d(box_state[2])
        at = (np.asarray(clocks, dtype=int), np.arange(self._num_fingers))
        ahead = at[0] > n
        r_W = s.p_BF[at] @ R.T
        p_target = box_state[:2] + r_W
        if ahead.any():  # a finger landing early runs its path faster
            near = s.landing[at] - at[0] <= int(round(g.landing_reflex.approach_time / s.period))
            rate = np.where(ahead, np.where(near, g.landing_reflex.approach_speedup, g.landing_reflex.speedup), 1.0)[
                :, None
            ]
        else:
            rate = np.ones((self._num_fingers, 1))
        v_target = box_state[3:5] + box_state[5] * perp(r_W) + rate * (s.v_BF[at] @ R.T)
        scale = s.force_scale[at]
        # A finger the QP may use is force-controlled: its spring fades with its force budget, so
        # that what it applies to the box is the QP's force. A tangential spring to a box-fixed
        # target fights the friction force as the sphere rolls (a slow in-grasp turn ran 0.05 rad
        # ahead); a lifting finger's normal spring pulled it off while the QP still counted on it.
        error = (1.0 - scale)[:, None] * (p_target - p_WF)
        kp = np.where(ahead, g.landing_reflex.tip_kp, g.grasp.tip_kp)[:, None]
        kd = np.where(ahead, g.landing_reflex.tip_kd, g.grasp.tip_kd)[:, None]
        spring = kp * error + kd * (v_target - v_WF)
        joints = (J_WF, np.einsum("fij,fi->fj", J_WF, spring) + g_hand)
        f_W, n_W = self.finger_forces(s, n, box_state, p_WF, estimates, joints, at=at, scale=scale)
        # The force acts on the sphere's surface, tip_radius from its centre along -n_W: through the
        # contact point's Jacobian J_C = J + perp(r_FC) [1 1] (link 2 turns at q1dot + q2dot), a
        # tangential force also turns the second link (without it a static hold settled 0.035 rad off).
        lever = np.sum(perp(-self._tip_radius * n_W) * f_W, axis=1)  # perp(r_FC) . f
        tau = np.einsum("fij,fi->fj", J_WF, spring + f_W) + lever[:, None] + g_hand
        if g.grasp.hand_dynamics:
            tau = tau + self.link_torques(s, n, q, box_state, r_W, v_target, J_WF, estimates)
        return self._u_from_tau @ tau.ravel()

    def link_torques(self, s: GraspSchedule, n, q, box_state, r_W, v_target, J_WF, estimates) -> np.ndarray:
        """(F, 2) the joint torques that move the fingers' own links (gains.grasp.hand_dynamics)."""
        R = rotation_2d(box_state[2])
        # The motors also move the links: a finger in contact accelerates with the box point it touches
        # (the box at its desired acceleration), so that its own inertia and damping do not eat the QP's
        # forces (Drake's gripper: 0.0083 kg m^2 links, reflected ~20 kg along a face it pushes).
        w = box_state[5]
        feedback = np.clip(self.desired_acceleration(s, n, box_state, estimates) - s.A[n], -ACCEL_LIMIT, ACCEL_LIMIT)
        accel = s.A[n] + feedback
        a_BF = (s.v_BF[min(n + 1, len(s.X) - 1)] - s.v_BF[max(n - 1, 0)]) / (2 * s.period)
        swinging = (1.0 - s.force_scale[n])[:, None]
        a_target = (
            accel[:2] + accel[2] * perp(r_W) - w**2 * r_W + swinging * (a_BF @ R.T + 2 * w * perp(s.v_BF[n] @ R.T))
        )
        # damped least squares: near a straight finger (q2 ~ 0) the exact inverse asks for unbounded torques
        JJt = J_WF @ np.swapaxes(J_WF, 1, 2) + SINGULAR_DAMPING**2 * np.eye(2)

        def inverse(x):
            return np.einsum("fji,fj->fi", J_WF, np.linalg.solve(JJt, x[..., None])[..., 0])

        vd = inverse(v_target)  # the joint rates that follow the targets
        M, motion = self._kinematics.dynamics(q, vd)
        r1, r2 = self._kinematics.fingers.links(q.reshape(-1, 2))
        bias = -(vd[:, :1] ** 2) * r1 - ((vd[:, 0] + vd[:, 1]) ** 2)[:, None] * r2  # Jdot qdot
        return motion + np.einsum("fij,fj->fi", M, inverse(a_target - bias))


class ClosedLoopGraspController(GraspController):
    """The grasp controller fed by the closed loop. Input ports as GraspController's, and
    `friction` (1: the friction estimate its cones follow, ConeFriction's), `mass_estimate` (1, kg),
    `reflex` (1, 0..1), `disturbance` (2, N in W; trajectotree.execution.closed_loop) and `clocks` (F: the
    schedule sample each finger follows, LandingReflex's). Output port `actuation` as GraspController's.
    Its cones are at mu x friction / scene.mu (the same safety factor on the estimate), the wrench uses
    the estimated mass and cancels the measured disturbance at once, and the QP keeps the joint
    torques within the motors'. The push reflex raises the object gains and the QP's target squeeze
    (a target, not a bound), puts its cones at push_reflex.friction_safety x the estimate and weights its
    torque residual by push_reflex.torque_weight: a three-finger grasp that barely opposes a push then spends
    what it has on the push without turning the box (each turn of the box is a grasp the plan never checked)."""

    TORQUE_ROWS = True

    def __init__(self, scene: Scene, gains: ControllerGains, *, mu: float):
        super().__init__(scene, gains, mu=mu)
        self.estimate_ports = EstimatePorts.declare(self, disturbance_size=2)
        self.clocks_port = self.DeclareVectorInputPort("clocks", scene.num_fingers)

    def estimates(self, context) -> Estimates:
        return self.estimate_ports.read(context)

    def clocks(self, context, schedule: GraspSchedule) -> np.ndarray:
        return self.clocks_port.Eval(context).astype(int)

    def grasp_forces(self, G, wrench, lambda_plan, scale, estimates: Estimates, normals, joints) -> np.ndarray:
        """As GraspController's, at the estimated friction, with the joint torques the forces add (to the
        other torques of `joints`) within the motors' and, during the push reflex, the squeeze the motors
        can make as the QP's target push (its least the plan's)."""
        g = self.gains
        n_W, t_W = normals
        J_WF, rest = joints
        A, lower, upper, room = torque_rows(J_WF, n_W, t_W, self._tip_radius, rest, self._tau_max)
        hi = scale * g.grasp.max_normal_force
        safety = self._friction_safety + estimates.reflex * max(
            g.push_reflex.friction_safety - self._friction_safety, 0.0
        )
        self._qp.set_friction(safety * estimates.mu)
        target = lambda_plan.copy()
        squeeze = estimates.reflex * np.minimum(scale * g.push_reflex.squeeze, np.minimum(room, hi))
        target[:, 0] = np.maximum(target[:, 0], squeeze)
        return self._qp.solve(
            G,
            wrench,
            target,
            np.minimum(scale * g.grasp.min_normal_force, np.minimum(room, hi)),
            hi,
            torque=(A, lower, upper),
            torque_weight=1.0 + estimates.reflex * (g.push_reflex.torque_weight - 1.0),
        )
