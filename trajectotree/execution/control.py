"""The two executors of a plan: the paper's fingertip impedance controller
(`ImpedanceController`, eq. 20) and the object-level `GraspController` (the default).

Fingertip impedance controller with gravity compensation (paper eq. 20):

    tau = sum_i J_WF_i^T (kp (p_ref_i - p_i) + kv (v_ref_i - v_i) + f_ref_i) + g_hand

p_i, v_i are the position and velocity of fingertip i (its sphere centre) in W,
J_WF_i its translational Jacobian, f_ref_i the planned force of finger i on the
box in W (the box pushes back with -f_ref_i, so the motors must supply J^T f_ref),
and g_hand the torques that cancel gravity on the links. The gains are the same
for every planner (paper Sec. IV-D). Torque limits are the plant's effort limits,
which Drake's discrete plant enforces on the actuation input.

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
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import ClarabelSolver, MathematicalProgram, OsqpSolver, SolverOptions
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem

from trajectotree.config import ControllerGains, SceneConfig
from trajectotree.execution.reference import GraspSchedule
from trajectotree.geometry import rotation_2d
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.kinematics import TwoLinkFinger, jacobian_from_links
from trajectotree.scene.plant import FingerGeometry, Scene, build_scene
from trajectotree.scene.statics import cone_rows, grasp_matrix_W, perp, torque_rows

ACCEL_LIMIT = np.array([0.0, 0.0, 5.0])  # m/s^2, m/s^2, rad/s^2: the box feedback the fingers' own inertia follows
SINGULAR_DAMPING = 0.01  # m, of the fingers' damped least-squares accelerations (a tenth of Drake's gripper's links)


def check_finger_major(scene: Scene) -> None:
    """ValueError unless the hand instance's positions are the description's joints in order
    (finger-major, each finger's from its base out): the controllers read the instance's state
    port as the planner's q."""
    if not scene.hand_state_is_finger_major:
        raise ValueError(
            f"hand {scene.config.hand}: its model's joints are not in the description's (finger-major) order"
        )


class ImpedanceController(LeafSystem):
    """Input ports: `hand_state` (the hand model instance's [q; v], 4F for F fingers), `p_WF_ref`,
    `v_WF_ref`, `f_W_ref` (2F each: finger-major (x, y) in W). Output port:
    `actuation` (2F, the plant's actuation input order)."""

    def __init__(self, scene_config: SceneConfig, gains: ControllerGains):
        super().__init__()
        self.gains = gains
        # Its own plant and context: the controller sees only the measured hand state.
        self._scene = build_scene(scene_config)
        check_finger_major(self._scene)
        self._plant, self._hand = self._scene.plant, self._scene.hand
        self._plant_context = self._plant.CreateDefaultContext()
        self._num_fingers = self._scene.num_fingers
        self._tip_frames = [self._scene.tip_frame(i) for i in range(self._num_fingers)]
        # u = B^T tau_v maps generalized forces to actuators (B is a selection: one actuator per joint).
        self._B = self._plant.MakeActuationMatrix()
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * self._scene.num_hand_joints)
        self.p_ref_port = self.DeclareVectorInputPort("p_WF_ref", 2 * self._num_fingers)
        self.v_ref_port = self.DeclareVectorInputPort("v_WF_ref", 2 * self._num_fingers)
        self.f_ref_port = self.DeclareVectorInputPort("f_W_ref", 2 * self._num_fingers)
        self.actuation_port = self.DeclareVectorOutputPort(
            "actuation", BasicVector(self._plant.num_actuators()), self.CalcActuation
        )

    def fingertip_kinematics(self, hand_state) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """p_WF (F, 2), v_WF (F, 2) and J_WF (F, 2, nv) at a hand state."""
        plant, ctx = self._plant, self._plant_context
        plant.SetPositionsAndVelocities(ctx, self._hand, hand_state)
        v = plant.GetVelocities(ctx)
        p_WF = np.empty((self._num_fingers, 2))
        J_WF = np.empty((self._num_fingers, 2, plant.num_velocities()))
        for i, frame in enumerate(self._tip_frames):
            p_WF[i] = frame.CalcPoseInWorld(ctx).translation()[:2]
            J_WF[i] = plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, frame, np.zeros(3), plant.world_frame(), plant.world_frame()
            )[:2]
        return p_WF, J_WF @ v, J_WF

    def compute_actuation(self, hand_state, p_ref, v_ref, f_ref) -> np.ndarray:
        """Eq. 20 for one hand state and references (each (F, 2) or flat (2F,))."""
        p_WF, v_WF, J_WF = self.fingertip_kinematics(hand_state)
        shape = (self._num_fingers, 2)
        F = (
            self.gains.impedance.kp * (np.reshape(p_ref, shape) - p_WF)
            + self.gains.impedance.kv * (np.reshape(v_ref, shape) - v_WF)
            + np.reshape(f_ref, shape)
        )
        tau_v = np.einsum("fiv,fi->v", J_WF, F) - self._plant.CalcGravityGeneralizedForces(self._plant_context)
        return self._B.T @ tau_v

    def CalcActuation(self, context, output):
        output.SetFromVector(
            self.compute_actuation(
                self.hand_state_port.Eval(context),
                self.p_ref_port.Eval(context),
                self.v_ref_port.Eval(context),
                self.f_ref_port.Eval(context),
            )
        )


class HandKinematics:
    """Closed-form kinematics (kinematics.TwoLinkFinger) and gravity torques of all the
    two-link fingers at once (the controller's hot path)."""

    def __init__(self, fingers: tuple[FingerGeometry, ...], gravity: float):
        self.fingers = TwoLinkFinger.stack(fingers)
        self._model = HandModel.from_fingers(fingers, gravity)  # CITO's hand dynamics: the same closed forms
        # dV/dq = [k1 cos a1 + k2 cos a12, k2 cos a12]
        self._k1, self._k2 = self._model.grav_1, self._model.grav_2
        self.damping = np.array([f.damping for f in fingers])  # (F, 2) N m s/rad

    def dynamics(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """At joint angles q and rates v (2F each): each finger's mass matrix M (F, 2, 2) and the
        torques its motion costs besides M qdd, Coriolis and joint damping, (F, 2)."""
        M = self._model.mass_matrices(np.ravel(q))
        q, v = np.reshape(q, (-1, 2)), np.reshape(v, (-1, 2))
        hs = self._model.mass_b * np.sin(q[:, 1])  # M12 = c + b cos q2: the Coriolis terms' b sin q2
        coriolis = np.column_stack([-hs * (2 * v[:, 0] * v[:, 1] + v[:, 1] ** 2), hs * v[:, 0] ** 2])
        return M, coriolis + self.damping * v

    def __call__(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At joint angles q (2F, finger-major): fingertip centres p_WF (F, 2), Jacobians
        J_WF (F, 2, 2) and the joint torques that hold the fingers up, g (F, 2)."""
        q = np.reshape(q, (-1, 2))
        r1, r2 = self.fingers.links(q)
        p = self.fingers.tip_from_links(r1, r2)
        c1, c12 = (np.cos(a) for a in self.fingers.angles(q))
        g = np.column_stack([self._k1 * c1 + self._k2 * c12, self._k2 * c12])
        return p, jacobian_from_links(r1, r2), g


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


def next_landing(force_scale: np.ndarray) -> np.ndarray:
    """(N, F) int: for each sample n and finger, the first sample >= n where the finger's force
    budget is full again (its next planned landing, or n itself while it holds), -1 if none."""
    N, F = force_scale.shape
    out = np.full((N, F), -1, dtype=int)
    nxt = np.full(F, -1, dtype=int)
    for n in range(N - 1, -1, -1):
        nxt = np.where(force_scale[n] >= 1.0, n, nxt)
        out[n] = nxt
    return out


@dataclass(frozen=True)
class Estimates:
    """What the closed loop (trajectotree.execution.closed_loop) tells the GraspController."""

    mu: float  # the friction coefficient estimate (the QP's cones: this x the controller's safety factor)
    mass: float  # kg, the box mass estimate (the desired wrench's gravity and inertia)
    reflex: float  # 0..1, the push reflex (squeeze and object gains raised in proportion)
    # (2,) N in W, the force on the box that its contacts and gravity do not explain (the desired wrench cancels it)
    disturbance: np.ndarray = field(default_factory=lambda: np.zeros(2))


class GraspController(LeafSystem):
    """Object-level grasp control of a planned box motion (see the module doc).
    Input ports: `box_state` (6: x, y, theta and their rates, in W, the box's planar
    joint) and `hand_state` (4F for F fingers: the hand's [q; v]); with closed_loop also `mu_estimate`,
    `mass_estimate`, `reflex` (1 each) and `disturbance` (2, N in W; all
    trajectotree.execution.closed_loop). Output port:
    `actuation` (2F, the plant's actuation order), updated every 1 / gains.rate_hz s and held
    in between. In open loop `mass` is the plan's and `mu` the friction its QP's cones allow
    (simulate passes max(search, controller friction_safety) x scene.mu), not the simulated
    plant's; in closed loop the cones are at mu x mu_estimate / scene.mu (the same safety
    factor on the estimate, which they follow over cone_time_constant), the wrench uses the
    estimated mass and cancels the measured disturbance at once, and the QP keeps the joint
    torques within the motors'. The reflex
    raises the object gains and the QP's target squeeze (a target, not a bound), puts its
    cones at reflex_friction_safety x the estimate and weights its torque residual by
    reflex_torque_weight: a three-finger grasp that barely opposes a push then spends what it
    has on the push without turning the box (each turn of the box is a grasp the plan never
    checked). The landing reflex (closed loop, landing_clocks): while the reflex is on or the
    friction estimate has fallen, a swinging finger runs its planned swing ahead to its next
    landing, so that the grasp has all its fingers again within tens of milliseconds."""

    def __init__(
        self,
        scene: Scene,
        schedule: GraspSchedule,
        gains: ControllerGains,
        *,
        mu: float,
        closed_loop: bool = False,
        mu_assumed: float | None = None,
    ):
        super().__init__()
        c = scene.config
        self.gains, self.schedule = gains, schedule
        self._kinematics, self._tip_radius = HandKinematics(scene.fingers, c.gravity), scene.tip_radius
        self._gravity = c.gravity
        self._shape = c.shape
        self._mass = c.box_mass
        self._scene_config = c
        self._inertia = c.inertia_zz()  # a uniform plate (the box: m (w^2 + h^2) / 12) unless scene.object_inertia
        self._friction_safety = mu / c.mu
        self._mu_assumed = c.mu if mu_assumed is None else mu_assumed  # the friction the plan in effect assumes
        self._tau_max = np.array([f.tau_max for f in scene.fingers])  # (F, 2) N m
        check_finger_major(scene)
        self._num_fingers, self._num_joints = scene.num_fingers, scene.num_hand_joints
        # m, the torque length of the wrench QP: the circumradius (the box's half diagonal)
        self._qp = GraspForceQp(
            mu, c.shape.circumradius, gains.grasp.wrench_weight, num_fingers=scene.num_fingers, torque_rows=closed_loop
        )
        B = scene.plant.MakeActuationMatrix()  # (nv, nu), a selection
        self._u_from_tau = B[scene.hand_v_indices].T  # hand-joint torques -> actuation
        self.box_state_port = self.DeclareVectorInputPort("box_state", 6)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * scene.num_hand_joints)
        self.closed_loop = closed_loop
        if closed_loop:
            self.mu_estimate_port = self.DeclareVectorInputPort("mu_estimate", 1)
            self.mass_estimate_port = self.DeclareVectorInputPort("mass_estimate", 1)
            self.reflex_port = self.DeclareVectorInputPort("reflex", 1)
            self.disturbance_port = self.DeclareVectorInputPort("disturbance", 2)
        state = self._actuation_state = self.DeclareDiscreteState(B.shape[1])
        if closed_loop:
            # Each finger's sample of the schedule (the landing reflex runs a swing ahead of the plan's clock).
            self._clock_state = self.DeclareDiscreteState(np.zeros(scene.num_fingers))
            self._landing = next_landing(schedule.force_scale)
            # The friction the QP's cones use: the estimate, low-pass filtered (cone_friction).
            self._cone_state = self.DeclareDiscreteState(np.array([self._mu_assumed]))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self.UpdateActuation)
        self.DeclareInitializationDiscreteUpdateEvent(self.InitializeActuation)
        self.actuation_port = self.DeclareStateOutputPort("actuation", state)

    def estimates(self, context) -> Estimates | None:
        """The closed loop's inputs (None in open loop)."""
        if not self.closed_loop:
            return None
        return Estimates(
            mu=float(self.mu_estimate_port.Eval(context)[0]),
            mass=float(self.mass_estimate_port.Eval(context)[0]),
            reflex=float(self.reflex_port.Eval(context)[0]),
            disturbance=np.array(self.disturbance_port.Eval(context)),
        )

    def InitializeActuation(self, context, discrete_state):
        """As UpdateActuation, with every finger on the schedule's own sample: a replanned phase
        carries the last phase's state over, but a landing it ran ahead belonged to the old plan
        (its samples ahead are the new plan's now; followed, they drew a finger along the wrong path)."""
        return self.UpdateActuation(context, discrete_state, restart=True)

    def UpdateActuation(self, context, discrete_state, restart: bool = False):
        estimates = self.estimates(context)
        t = context.get_time()
        if estimates is None:
            discrete_state.set_value(
                self.compute_actuation(t, self.box_state_port.Eval(context), self.hand_state_port.Eval(context))
            )
            return EventStatus.Succeeded()
        previous = context.get_discrete_state(self._clock_state).get_value().astype(int)
        if restart:
            previous = np.full_like(previous, self.schedule.index(t))
        box_state, hand_state = self.box_state_port.Eval(context), self.hand_state_port.Eval(context)
        lag = self.path_lag(previous, box_state, hand_state)
        clocks = self.landing_clocks(self.schedule.index(t), previous, estimates, lag)
        cone = self.cone_friction(context.get_discrete_state(self._cone_state).get_value()[0], estimates.mu)
        discrete_state.get_mutable_vector(self._cone_state).SetFromVector([cone])
        estimates = replace(estimates, mu=cone)
        discrete_state.get_mutable_vector(self._clock_state).SetFromVector(clocks.astype(float))
        discrete_state.get_mutable_vector(self._actuation_state).SetFromVector(
            self.compute_actuation(t, box_state, hand_state, estimates, clocks)
        )
        return EventStatus.Succeeded()

    def cone_friction(self, previous: float, estimate: float) -> float:
        """The friction of the QP's cones one control period after `previous`: a first-order lag
        (gains.grasp.cone_time_constant) towards the friction `estimate`, so that the grasp forces move
        over tens of milliseconds when the estimate falls, not in one step."""
        tau = self.gains.grasp.cone_time_constant
        if tau <= 0.0:
            return estimate
        return previous + (estimate - previous) * min(1.0 / (self.gains.rate_hz * tau), 1.0)

    def landing_triggered(self, estimates: Estimates) -> bool:
        """The landing reflex is wanted: a push is on, or the friction estimate fell
        gains.landing_reflex.friction_drop below the plan's (its stances of fewer fingers may slip)."""
        g = self.gains
        return estimates.reflex > 0.0 or estimates.mu < self._mu_assumed - g.landing_reflex.friction_drop

    def path_lag(self, clocks, box_state, hand_state) -> np.ndarray:
        """(F,) m, how far each measured fingertip is from its target at its schedule sample `clocks`."""
        p_WF = self._kinematics(hand_state[: self._num_joints])[0]
        R = rotation_2d(box_state[2])
        clocks = np.minimum(clocks, len(self.schedule.X) - 1)
        p_target = box_state[:2] + self.schedule.p_BF[clocks, np.arange(self._num_fingers)] @ R.T
        return np.linalg.norm(p_target - p_WF, axis=1)

    def landing_clocks(self, n: int, previous: np.ndarray, estimates: Estimates, lag=None) -> np.ndarray:
        """(F,) the schedule sample each finger follows at plan sample n. The plan's (n), but a
        finger that swings while the landing reflex is wanted (or that already runs ahead: a
        landing once begun is finished) runs its swing gains.landing_reflex.speedup x as fast, up to its
        next planned landing, and then holds there until the plan catches up: its box-frame
        path lifted as planned, so that it lands where the plan lands it, only sooner. Its sample waits
        while the fingertip lags its target by more than gains.landing_reflex.lag (`lag` (F,) m, path_lag; None:
        none lags): a target run far ahead drew the finger after it at 3 m/s into the box."""
        # within this schedule: a replanning phase's controller takes the last phase's state
        clocks = np.minimum(np.maximum(previous, n), len(self.schedule.X) - 1)
        if self.gains.landing_reflex.speedup <= 1.0:
            return np.full(self._num_fingers, n)
        g = self.gains
        wanted = self.landing_triggered(estimates)
        approach = int(round(g.landing_reflex.approach_time / self.schedule.period))
        for i, c in enumerate(clocks):
            landing = self._landing[c, i]
            if landing < 0 or self.schedule.force_scale[c, i] >= 1.0:
                continue  # holding (or landed early and waiting), or no landing ahead
            if (wanted or c > n) and (lag is None or lag[i] <= g.landing_reflex.lag):
                # The last land_approach_time of the path slower: at the full speed-up the sphere hit the box
                # 4.5 mm deep with 9 N and knocked the other fingers off.
                speedup = g.landing_reflex.speedup if landing - c > approach else g.landing_reflex.approach_speedup
                clocks[i] = min(max(previous[i], n - 1) + int(round(speedup)), landing)
        return clocks

    def desired_acceleration(self, n: int, box_state, estimates: Estimates | None = None) -> np.ndarray:
        """(3,) the box's desired acceleration at sample n: the plan's, with pose and velocity feedback."""
        s, g = self.schedule, self.gains
        error = s.X[n] - box_state[:3]
        error[2] = (error[2] + np.pi) % (2 * np.pi) - np.pi
        kp, kd = g.grasp.object_kp, g.grasp.object_kd
        if estimates is not None:
            # kd grows with the square root of kp: the same damping ratio, a faster response.
            boost = 1.0 + estimates.reflex * (g.push_reflex.gain - 1.0)
            kp, kd = boost * g.grasp.object_kp, np.sqrt(boost) * g.grasp.object_kd
        return s.A[n] + kp * error + kd * (s.V[n] - box_state[3:])

    def desired_wrench(self, n: int, box_state, estimates: Estimates | None = None) -> np.ndarray:
        """(f_x N, f_y N, torque N m) the fingers should apply to the box at sample n."""
        g = self.gains
        if estimates is None:
            mass, inertia = self._mass, self._inertia
        else:
            mass, inertia = estimates.mass, self._scene_config.inertia_zz(estimates.mass)
        a = self.desired_acceleration(n, box_state, estimates)
        wrench = np.array([mass * a[0], mass * (a[1] + self._gravity), inertia * a[2]])
        if estimates is not None:
            wrench[:2] -= g.push_reflex.disturbance_feedforward * estimates.disturbance
        return wrench

    def finger_forces(
        self, n: int, box_state, p_WF, estimates: Estimates | None = None, joints=None, *, at=None, scale=None
    ) -> tuple[np.ndarray, np.ndarray]:
        """f_W (F, 2), the force each finger should apply to the box at sample n (QP),
        and n_W (F, 2), the outward normals of the faces it pushes on. The forces act
        where the measured fingertips p_WF (F, 2) touch the faces: a sphere rolls along
        the face as the box turns, and with the planned points instead, 2 mm of rolling
        under 1 N grips left a slow in-grasp turn 0.03 rad behind. The normals too are
        the object's at those points (the box's: its faces'), not the planned contacts':
        on a disc, spheres that rolled 15-30 deg around it from their planned contacts
        left the planned normals that far off, the QP credited the squeeze with a torque
        a disc's normals cannot make, squeezed to 3 N and let go (4 of 12 disc goals
        dropped). In closed loop (`estimates`), `joints` = (J_WF (F, 2, 2), the other
        joint torques (F, 2)) bound the torques the forces add."""
        s, g = self.schedule, self.gains
        R = rotation_2d(box_state[2])
        p_BF = (p_WF - box_state[:2]) @ R  # R^T (p_WF - p): the measured fingertips in B
        n_W = self._shape.face_normals(self._shape.nearest_points(p_BF)) @ R.T
        t_W = perp(n_W)
        r_W = p_WF - self._tip_radius * n_W - box_state[:2]  # contact points, from the box origin
        G = grasp_matrix_W(r_W, n_W)
        at = (n, slice(None)) if at is None else at  # each finger's sample (all n but a finger landing early)
        scale = s.force_scale[at] if scale is None else scale
        if estimates is None:
            lam = self._qp.solve(
                G,
                self.desired_wrench(n, box_state),
                s.lambda_plan[at],
                scale * g.grasp.min_normal_force,
                scale * g.grasp.max_normal_force,
            )
        else:
            J_WF, rest = joints
            A, lower, upper, room = torque_rows(J_WF, n_W, t_W, self._tip_radius, rest, self._tau_max)
            hi = scale * g.grasp.max_normal_force
            safety = self._friction_safety + estimates.reflex * max(
                g.push_reflex.friction_safety - self._friction_safety, 0.0
            )
            self._qp.set_friction(safety * estimates.mu)
            # During the reflex the squeeze the motors can make is the QP's target push, its least the plan's.
            target = s.lambda_plan[at].copy()
            squeeze = estimates.reflex * np.minimum(scale * g.push_reflex.squeeze, np.minimum(room, hi))
            target[:, 0] = np.maximum(target[:, 0], squeeze)
            lam = self._qp.solve(
                G,
                self.desired_wrench(n, box_state, estimates),
                target,
                np.minimum(scale * g.grasp.min_normal_force, np.minimum(room, hi)),
                hi,
                torque=(A, lower, upper),
                torque_weight=1.0 + estimates.reflex * (g.push_reflex.torque_weight - 1.0),
            )
        return -lam[:, :1] * n_W + lam[:, 1:] * t_W, n_W

    def compute_actuation(
        self, t: float, box_state, hand_state, estimates: Estimates | None = None, clocks=None
    ) -> np.ndarray:
        """The actuation at time t; `clocks` (F,) the schedule sample each finger follows (closed
        loop's landing reflex, landing_clocks; None: the plan's sample for all)."""
        s, g = self.schedule, self.gains
        n = s.index(t)
        q, v = hand_state[: self._num_joints], hand_state[self._num_joints :]
        p_WF, J_WF, g_hand = self._kinematics(q)
        v_WF = np.einsum("fij,fj->fi", J_WF, v.reshape(self._num_fingers, 2))
        R = rotation_2d(box_state[2])
        fingers = np.arange(self._num_fingers)
        at = (n, slice(None)) if clocks is None else (np.asarray(clocks, dtype=int), fingers)
        ahead = np.zeros(self._num_fingers, dtype=bool) if clocks is None else at[0] > n
        r_W = s.p_BF[at] @ R.T
        p_target = box_state[:2] + r_W
        if ahead.any():  # a finger landing early runs its path faster
            near = self._landing[at] - at[0] <= int(round(g.landing_reflex.approach_time / s.period))
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
        joints = None
        if estimates is not None:
            joints = (J_WF, np.einsum("fij,fi->fj", J_WF, spring) + g_hand)
        f_W, n_W = self.finger_forces(n, box_state, p_WF, estimates, joints, at=at, scale=scale)
        # The force acts on the sphere's surface, tip_radius from its centre along -n_W: through the
        # contact point's Jacobian J_C = J + perp(r_FC) [1 1] (link 2 turns at q1dot + q2dot), a
        # tangential force also turns the second link (without it a static hold settled 0.035 rad off).
        lever = np.sum(perp(-self._tip_radius * n_W) * f_W, axis=1)  # perp(r_FC) . f
        tau = np.einsum("fij,fi->fj", J_WF, spring + f_W) + lever[:, None] + g_hand
        if g.grasp.hand_dynamics:
            tau = tau + self.link_torques(n, q, box_state, r_W, v_target, J_WF, estimates)
        return self._u_from_tau @ tau.ravel()

    def link_torques(self, n, q, box_state, r_W, v_target, J_WF, estimates) -> np.ndarray:
        """(F, 2) the joint torques that move the fingers' own links (gains.grasp.hand_dynamics)."""
        s = self.schedule
        R = rotation_2d(box_state[2])
        # The motors also move the links: a finger in contact accelerates with the box point it touches
        # (the box at its desired acceleration), so that its own inertia and damping do not eat the QP's
        # forces (Drake's gripper: 0.0083 kg m^2 links, reflected ~20 kg along a face it pushes).
        w = box_state[5]
        feedback = np.clip(self.desired_acceleration(n, box_state, estimates) - s.A[n], -ACCEL_LIMIT, ACCEL_LIMIT)
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
