"""The closed loop around the GraspController (simulate --closed-loop): a watch of the
contacts, online estimates of what the plan assumed, and a reflex for pushes.

Five LeafSystems, each with its results in discrete state behind named output ports (so that
a replanner can read them as the controller does), all periodic at ControllerGains.rate_hz
but the ObjectMonitor, which samples every plant step:

One class of each for both dimensions: an `ObjectLayout` says where the object's pose and velocity lie in its
joint's state and which of its generalized velocities (and forces) translate it, the planar joint's
(`PLANAR_OBJECT`: [x, y, theta] and their rates; a wrench f_x, f_y, torque) or the quaternion floating joint's
(`SPACE_OBJECT`: [qw, qx, qy, qz, px, py, pz] and [w_W, v_W]; a wrench [torque; force] in W). Sizes below are the
plane's, with the layout's in brackets where space differs.

- `ContactMonitor` reads the plant's `contact_results` and the measured `box_state` and
  reports per finger `in_contact`, `slipping` (the relative tangential velocity at a contact
  point above controller.estimators.slip_speed while the finger pushes at least slip_min_force),
  `force_ratio` |f_t| / f_n and `normal_force` of its force on the box and its `slip_speed`;
  and the box's `tracking_error` (measured - planned pose).
- `ObjectMonitor` reads the measured `box_state` and the plant's generalized contact forces
  on the box and reports the box's `acceleration` (its velocity change over the step) and the
  hand's `contact_force` on it in the same step.
- `FrictionEstimator` (`mu_estimate`): starts at the plan's scene.mu; a loaded contact that
  slides steadily for slip_confirm_time lowers it to the median ratio |f_t| / f_n of the slide
  (a sliding contact rides its friction cone), never below controller.estimators.friction_floor, and
  nothing raises it.
- `MassEstimator` (`mass_estimate`): starts at the plan's mass and low-pass filters the
  hand's vertical force on the box over (g + a_y) while the box barely accelerates.
- `PushReflex` (`disturbance`, `reflex`): the force on the box that neither the contacts nor
  gravity explain (m a - f - m g, with the estimated mass); the reflex, 0..1, is 1 once it
  exceeds reflex_force for reflex_confirm_time, held reflex_hold s after it subsides, then
  fading over reflex_release s.

The ClosedLoopGraspController (trajectotree.execution.control) reads mu_estimate (through
reflexes.ConeFriction), mass_estimate, reflex and
disturbance (its desired wrench cancels the disturbance, disturbance-observer style). Each
system reads the others' state as of their last update, as sampled controllers do.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import EventStatus, LeafSystem

from trajectotree.config import ControllerGains
from trajectotree.execution.in_effect import declare_plan_input
from trajectotree.geometry import quaternion_error_W, wrap_angle
from trajectotree.scene.hand import HandDescription, finger_bodies

# N, a finger pushing less is out of contact: a contact that opens leaves forces of 1e-18 N, whose
# ratio |f_t| / f_n means nothing.
CONTACT_FORCE = 1e-3


# The largest relative change of a contact's normal force over a control period (1), and the fastest its
# contact points may open or close (m/s), for a slide sample to count as evidence of the friction
# (FrictionEstimator): a sphere pressed over a box corner at 2 mm/s slid at 0.25-0.3 in a world of 0.4.
STEADY_NORMAL_FORCE = 0.05
STEADY_APPROACH_SPEED = 2e-4


def planar_pose_error(box_state, schedule, n: int) -> np.ndarray:
    """(3,) the planar object's measured - planned pose at sample n of a GraspSchedule: m, m, rad (wrapped)."""
    error = box_state[:3] - schedule.X[n]
    error[2] = wrap_angle(error[2])
    return error


def space_pose_error(box_state, schedule, n: int) -> np.ndarray:
    """(6,) the cube's measured - planned pose at sample n of a SpaceSchedule, in its velocities' layout: the
    rotation vector (rad, in W) that turns the planned orientation onto the measured one, then the centre's offset
    (m, in W)."""
    quat = box_state[:4] / np.linalg.norm(box_state[:4])
    return np.concatenate([-quaternion_error_W(schedule.x[n, :4], quat), box_state[4:7] - schedule.x[n, 4:]])


@dataclass(frozen=True)
class ObjectLayout:
    """The object's state as its joint lays it out: `num_positions` positions, then `num_velocities` velocities
    (the plant's generalized contact forces on it have the velocities' layout), `linear` the [start, stop) of the
    velocities that translate it (the rest turn it), `vertical` the index of the one along gravity (up), and
    `pose_error` (box_state, schedule, sample) -> the measured - planned pose in the velocities' layout."""

    num_positions: int
    num_velocities: int
    linear: tuple[int, int]
    vertical: int
    pose_error: Callable[..., np.ndarray]

    @property
    def state_size(self) -> int:
        return self.num_positions + self.num_velocities

    @property
    def dimension(self) -> int:
        """2 in the plane, 3 in space: the translations' (and a contact force's) dimension."""
        return self.linear[1] - self.linear[0]

    def velocity(self, box_state) -> np.ndarray:
        return box_state[self.num_positions :]

    def translational(self, values) -> np.ndarray:
        """The translational components of velocities, accelerations or generalized forces in this layout."""
        return values[self.linear[0] : self.linear[1]]

    def gravity_W(self, gravity: float) -> np.ndarray:
        """(dimension,) m/s^2, gravity's acceleration along the translations."""
        g = np.zeros(self.dimension)
        g[self.vertical - self.linear[0]] = -gravity
        return g

    def error_scale(self, torque_length: float) -> np.ndarray:
        """(num_velocities,) what turns a pose error into metres: 1 for the translations, torque_length m for
        the angles (an angle at the object's rim)."""
        scale = np.full(self.num_velocities, torque_length)
        scale[self.linear[0] : self.linear[1]] = 1.0
        return scale


PLANAR_OBJECT = ObjectLayout(3, 3, (0, 2), 1, planar_pose_error)  # the planar joint: gravity along -y
SPACE_OBJECT = ObjectLayout(7, 6, (3, 6), 5, space_pose_error)  # the quaternion floating joint: gravity along -z


def low_pass_step(previous, target, gain: float):
    """One step of a discrete first-order low-pass filter: `gain` (0..1, the sample period over the
    time constant, at most 1) of the way from `previous` to `target`."""
    return previous + gain * (target - previous)


@dataclass(frozen=True)
class FingerContacts:
    """What the point contacts between the hand and the box say, per finger (F,) and in total."""

    normal_force: np.ndarray  # (F,) N, each finger's push along the box's inward normals
    tangential_force: np.ndarray  # (F, 2 [3]) N, its force on the box along the faces, in W
    slip_speed: np.ndarray  # (F,) m/s, the fastest relative tangential velocity at its contact points
    approach_speed: np.ndarray  # (F,) m/s, the fastest rate at which one of them opens or closes (|separation speed|)

    @property
    def in_contact(self) -> np.ndarray:
        return self.normal_force > CONTACT_FORCE

    @property
    def force_ratio(self) -> np.ndarray:
        """(F,) |f_t| / f_n (0 out of contact)."""
        tangential = np.linalg.norm(self.tangential_force, axis=1)
        return np.divide(tangential, self.normal_force, out=np.zeros(len(tangential)), where=self.in_contact)


def finger_contacts(
    results: ContactResults, finger_of_body: dict, box_body, num_fingers: int, dimension: int = 2
) -> FingerContacts:
    """FingerContacts of `num_fingers` fingers from the plant's point-pair contact results;
    `finger_of_body` maps the body index of each finger link to its finger; `dimension` 2 keeps the forces'
    components in the plane (x, y), 3 all of them."""
    normal = np.zeros(num_fingers)
    tangential = np.zeros((num_fingers, dimension))
    slip = np.zeros(num_fingers)
    approach = np.zeros(num_fingers)
    for k in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(k)
        a, b = info.bodyA_index(), info.bodyB_index()
        if b == box_body and a in finger_of_body:  # nhat_BA_W points from B (the box) to A: out of the box
            f_box, n_out, i = info.contact_force(), info.point_pair().nhat_BA_W, finger_of_body[a]
        elif a == box_body and b in finger_of_body:
            f_box, n_out, i = -info.contact_force(), -info.point_pair().nhat_BA_W, finger_of_body[b]
        else:
            continue
        push = -float(f_box @ n_out)
        normal[i] += push
        tangential[i] += (f_box + push * n_out)[:dimension]
        slip[i] = max(slip[i], info.slip_speed())
        approach[i] = max(approach[i], abs(info.separation_speed()))
    return FingerContacts(normal_force=normal, tangential_force=tangential, slip_speed=slip, approach_speed=approach)


class PeriodicSystem(LeafSystem):
    """A LeafSystem whose state is groups of discrete values, all set by one periodic update
    (`update(context) -> {group: values}`, groups it omits keep their values) every
    `period` s and at initialization; `outputs` name the groups behind output ports of
    those names, `internal` the others (name: initial values, each)."""

    def __init__(self, period: float, outputs: dict, internal: dict | None = None):
        super().__init__()
        self.period = period
        self._groups = {
            name: self.DeclareDiscreteState(np.atleast_1d(np.asarray(v, dtype=float)))
            for name, v in {**outputs, **(internal or {})}.items()
        }
        for name in outputs:
            self.DeclareStateOutputPort(name, self._groups[name])
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)
        self.DeclareInitializationDiscreteUpdateEvent(self._Update)

    def state(self, context, name: str) -> np.ndarray:
        return context.get_discrete_state(self._groups[name]).get_value()

    def _Update(self, context, discrete_state):
        for name, values in self.update(context).items():
            discrete_state.get_mutable_vector(self._groups[name]).SetFromVector(np.atleast_1d(values))
        return EventStatus.Succeeded()

    def update(self, context) -> dict:
        raise NotImplementedError


def planar_finger_of_body(plant, hand, description: HandDescription) -> dict:
    """{body index: finger} of every link of each finger of a planar hand (description's order)."""
    return {body.index(): i for i, f in enumerate(description.fingers) for body in finger_bodies(plant, hand, f)}


class ContactMonitor(PeriodicSystem):
    """Input ports `contact_results` (the plant's), `box_state` (6 [13]: the object's joint state, `layout`'s)
    and `plan` (the PlanInEffect, trajectotree.execution.in_effect). Output ports, per finger
    (F each): `in_contact` (1/0), `slipping` (1/0),
    `force_ratio`, `normal_force` (N), `slip_speed` and `approach_speed` (m/s: how fast a
    contact point slides, and opens or closes); and the box's `tracking_error` (3 [6]: measured -
    planned pose, layout.pose_error: theta wrapped in the plane). `finger_of_body` maps the body index of each
    finger link of the caller's plant to its finger (planar_finger_of_body), `box_body` is the object's."""

    def __init__(
        self,
        finger_of_body: dict,
        box_body,
        num_fingers: int,
        gains: ControllerGains,
        layout: ObjectLayout = PLANAR_OBJECT,
    ):
        self._num_fingers = num_fingers
        four = np.zeros(self._num_fingers)
        outputs = {"in_contact": four, "slipping": four, "force_ratio": four, "normal_force": four}
        outputs |= {"slip_speed": four, "approach_speed": four}
        super().__init__(1.0 / gains.rate_hz, outputs | {"tracking_error": np.zeros(layout.num_velocities)})
        self.gains, self.layout = gains, layout
        self._finger_of_body, self._box_body = dict(finger_of_body), box_body
        self.contact_results_port = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self.box_state_port = self.DeclareVectorInputPort("box_state", layout.state_size)
        self.plan_port = declare_plan_input(self)

    def update(self, context) -> dict:
        s, g = self.plan_port.Eval(context).schedule, self.gains
        contacts = finger_contacts(
            self.contact_results_port.Eval(context),
            self._finger_of_body,
            self._box_body,
            self._num_fingers,
            self.layout.dimension,
        )
        error = self.layout.pose_error(self.box_state_port.Eval(context), s, s.index(context.get_time()))
        return {
            "in_contact": contacts.in_contact,
            "slipping": (contacts.normal_force >= g.estimators.slip_min_force)
            & (contacts.slip_speed > g.estimators.slip_speed),
            "force_ratio": contacts.force_ratio,
            "normal_force": contacts.normal_force,
            "slip_speed": contacts.slip_speed,
            "approach_speed": contacts.approach_speed,
            "tracking_error": error,
        }


class ObjectMonitor(PeriodicSystem):
    """Input ports `box_state` (6 [13]) and `box_contact_forces` (3 [6]: the plant's generalized contact
    forces on the box, f_x N, f_y N in W and the torque N m [the torque and the force in W]). Output ports, sampled
    together at the plant's step: `acceleration` (3 [6], the box's measured velocity change over the step
    / the step) and `contact_force` (3 [6], the contact forces of that step). At the plant's step,
    not the control rate: the plant reports the contact forces of the step that led to the
    measured state, so the velocity change over one step is exactly what they, gravity (and a
    push) explain; over two steps a finger landing's force, which alternates between them,
    left 2-3 N unexplained for 4 ms."""

    def __init__(self, time_step: float, layout: ObjectLayout = PLANAR_OBJECT):
        three = np.zeros(layout.num_velocities)
        super().__init__(
            time_step, {"acceleration": three, "contact_force": three}, {"velocity": three, "started": 0.0}
        )
        self.layout = layout
        self.box_state_port = self.DeclareVectorInputPort("box_state", layout.state_size)
        self.box_contact_forces_port = self.DeclareVectorInputPort("box_contact_forces", layout.num_velocities)

    def update(self, context) -> dict:
        velocity = self.layout.velocity(self.box_state_port.Eval(context))
        # No velocity before the first update: the first acceleration is zero, not a jump from rest.
        started = self.state(context, "started")[0] > 0.0
        accel = (
            (velocity - self.state(context, "velocity")) / self.period
            if started
            else np.zeros(self.layout.num_velocities)
        )
        return {
            "acceleration": accel,
            "contact_force": self.box_contact_forces_port.Eval(context),
            "velocity": velocity,
            "started": 1.0,
        }


class FrictionEstimator(PeriodicSystem):
    """Input ports `slipping`, `force_ratio`, `normal_force` and `approach_speed` (F each,
    ContactMonitor's), `tracking_error` (3 [6], ContactMonitor's), `reflex` (1, PushReflex's) and `plan` (the
    PlanInEffect, whose schedule says when the plan loads a finger).
    Output port `mu_estimate` (1): the friction the plan assumed, `mu_assumed` (its scene.mu; not the
    search's planning friction config.mu_plan), until a contact has slid
    steadily for gains.estimators.slip_confirm_time, then the least median ratio |f_t| / f_n over such a
    slide's last slip_confirm_time, never below gains.estimators.friction_floor and never raised.
    A slide sample counts while no reflex is on and the box is within
    gains.estimators.friction_evidence_error of the plan (its position, and its angles times
    `torque_length`: layout.error_scale), when the plan loads the finger fully (its schedule's force_scale 1), it
    pushes with at least gains.estimators.friction_evidence_force, its normal force changed by at most
    STEADY_NORMAL_FORCE since the last sample and its contact neither opens nor closes faster
    than STEADY_APPROACH_SPEED: in Drake's lagged contact model (friction bounded by the
    previous step's elastic normal force) a light contact, or one whose penetration changes (a
    landing, a finger letting go, a sphere pressed over a corner), slides at a ratio down to
    half the world's friction (a nominal run at mu 0.7 read 0.38 and 0.51 from such slides),
    and so do the contacts of a pushed box or one already off the plan (0.52-0.65 after 6 N
    pushes at 0.7, 0.26-0.38 at 0.3-0.4). The median, not the mean: single steady ratios still
    lie up to 0.05 below or 0.02 above it."""

    def __init__(
        self,
        mu_assumed: float,
        torque_length: float,
        num_fingers: int,
        gains: ControllerGains,
        layout: ObjectLayout = PLANAR_OBJECT,
    ):
        period = 1.0 / gains.rate_hz
        # Samples in slip_confirm_time (at least one); a period's rounding must not drop one.
        self._window = max(int(np.floor(gains.estimators.slip_confirm_time / period + 1e-9)), 1)
        self._num_fingers = num_fingers
        four = np.zeros(self._num_fingers)
        internal = {
            "slide_samples": four,
            "slide_ratios": np.zeros(self._num_fingers * self._window),
            "normal_force": four,
        }
        super().__init__(period, {"mu_estimate": max(mu_assumed, gains.estimators.friction_floor)}, internal)
        self.gains = gains
        self.slipping_port = self.DeclareVectorInputPort("slipping", self._num_fingers)
        self.force_ratio_port = self.DeclareVectorInputPort("force_ratio", self._num_fingers)
        self.normal_force_port = self.DeclareVectorInputPort("normal_force", self._num_fingers)
        self.approach_speed_port = self.DeclareVectorInputPort("approach_speed", self._num_fingers)
        self.reflex_port = self.DeclareVectorInputPort("reflex", 1)
        self.tracking_error_port = self.DeclareVectorInputPort("tracking_error", layout.num_velocities)
        self.plan_port = declare_plan_input(self)
        self._scale = layout.error_scale(torque_length)  # rad -> m at the box's rim

    def update(self, context) -> dict:
        normal = self.normal_force_port.Eval(context)
        steady = np.abs(normal - self.state(context, "normal_force")) <= STEADY_NORMAL_FORCE * normal
        steady &= self.approach_speed_port.Eval(context) <= STEADY_APPROACH_SPEED
        schedule = self.plan_port.Eval(context).schedule
        loaded = schedule.force_scale[schedule.index(context.get_time())] >= 1.0
        pushing = normal >= self.gains.estimators.friction_evidence_force
        pushed = self.reflex_port.Eval(context)[0] > 0.0
        off = (
            np.abs(self.tracking_error_port.Eval(context) * self._scale).max()
            > self.gains.estimators.friction_evidence_error
        )
        valid = (self.slipping_port.Eval(context) > 0.5) & loaded & steady & pushing & (not pushed) & (not off)
        samples = np.where(valid, self.state(context, "slide_samples") + 1.0, 0.0)  # a slide ends: reset
        ratios = self.state(context, "slide_ratios").reshape(self._num_fingers, self._window)
        ratios = np.column_stack([ratios[:, 1:], self.force_ratio_port.Eval(context)])  # the last window, oldest first
        mu = self.state(context, "mu_estimate")[0]
        confirmed = samples >= self._window
        if confirmed.any():
            mu = min(mu, float(np.min(np.median(ratios[confirmed], axis=1))))
        return {
            "mu_estimate": max(mu, self.gains.estimators.friction_floor),
            "slide_samples": samples,
            "slide_ratios": ratios.ravel(),
            "normal_force": normal,
        }


class MassEstimator(PeriodicSystem):
    """Input ports `contact_force` (3 [6], the hand's force on the box in W and its torque) and
    `acceleration` (3 [6], the box's; both ObjectMonitor's). Output port `mass_estimate` (1, kg):
    the plan's mass, low-pass filtered (gains.estimators.mass_time_constant) towards f_up / (g + a_up) (y up in the
    plane, z in space) whenever the box's translational acceleration is below gains.estimators.mass_accel_max,
    within gains.estimators.mass_estimate_range x the plan's mass."""

    def __init__(self, mass_plan: float, gravity: float, gains: ControllerGains, layout: ObjectLayout = PLANAR_OBJECT):
        super().__init__(1.0 / gains.rate_hz, {"mass_estimate": mass_plan})
        self.gains, self._gravity, self.layout = gains, gravity, layout
        self._range = (
            gains.estimators.mass_estimate_range[0] * mass_plan,
            gains.estimators.mass_estimate_range[1] * mass_plan,
        )
        self._gain = min(
            self.period / gains.estimators.mass_time_constant, 1.0
        )  # the filter's step towards a measurement
        self.contact_force_port = self.DeclareVectorInputPort("contact_force", layout.num_velocities)
        self.acceleration_port = self.DeclareVectorInputPort("acceleration", layout.num_velocities)

    def update(self, context) -> dict:
        up = self.layout.vertical
        accel, support = self.acceleration_port.Eval(context), self.contact_force_port.Eval(context)[up]
        # Not held up (the first sample, before any contact force, among them): nothing to weigh.
        if np.linalg.norm(self.layout.translational(accel)) >= self.gains.estimators.mass_accel_max or support <= 0.0:
            return {}
        mass = self.state(context, "mass_estimate")[0]
        measured = support / (self._gravity + accel[up])
        return {"mass_estimate": float(np.clip(low_pass_step(mass, measured, self._gain), *self._range))}


class PushReflex(PeriodicSystem):
    """Input ports `acceleration` and `contact_force` (3 [6] each, the box's: ObjectMonitor's) and
    `mass_estimate` (1). Output ports `disturbance` (2 [3], N in W): the force on the box
    that the hand's measured force and gravity do not explain, m a - f - m g; and `reflex`
    (1): 1 once |disturbance| has exceeded gains.push_reflex.force for reflex_confirm_time, held
    while it does and gains.push_reflex.hold s after, then falling linearly to 0 over
    gains.push_reflex.release s. The disturbance, not the box's acceleration against the plan's:
    the fingers push back within 10 ms, after which a 3 N push barely accelerates the box,
    and a finger landing jolts it by 40 m/s^2 for a few ms, which its measured force
    explains."""

    def __init__(self, gravity: float, gains: ControllerGains, layout: ObjectLayout = PLANAR_OBJECT):
        period = 1.0 / gains.rate_hz
        self._confirm = max(int(np.floor(gains.push_reflex.confirm_time / period + 1e-9)), 1)  # samples
        internal = {"pushed_samples": 0.0, "quiet_time": np.inf}
        super().__init__(period, {"disturbance": np.zeros(layout.dimension), "reflex": 0.0}, internal)
        self.gains, self.layout = gains, layout
        self._gravity_W = layout.gravity_W(gravity)
        self.acceleration_port = self.DeclareVectorInputPort("acceleration", layout.num_velocities)
        self.contact_force_port = self.DeclareVectorInputPort("contact_force", layout.num_velocities)
        self.mass_estimate_port = self.DeclareVectorInputPort("mass_estimate", 1)

    def update(self, context) -> dict:
        g = self.gains
        mass = self.mass_estimate_port.Eval(context)[0]
        accel = self.layout.translational(self.acceleration_port.Eval(context))
        disturbance = mass * (accel - self._gravity_W) - self.layout.translational(
            self.contact_force_port.Eval(context)
        )
        pushed = np.linalg.norm(disturbance) > g.push_reflex.force
        samples = self.state(context, "pushed_samples")[0] + 1.0 if pushed else 0.0
        quiet = 0.0 if samples >= self._confirm else self.state(context, "quiet_time")[0] + self.period
        after = quiet - g.push_reflex.hold
        level = (
            1.0
            if after <= 0.0
            else (max(0.0, 1.0 - after / g.push_reflex.release) if g.push_reflex.release > 0 else 0.0)
        )
        return {"disturbance": disturbance, "reflex": level, "pushed_samples": samples, "quiet_time": quiet}
