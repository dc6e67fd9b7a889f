"""The closed loop's two systems between its estimates and the grasp controller
(trajectotree.execution.control.ClosedLoopGraspController), each its own LeafSystem:

- `LandingReflex` (`clocks`): the schedule sample each finger follows. The plan's, but while the push
  reflex is on or the friction estimate has fallen, a swinging finger runs its planned swing ahead to
  its next landing, so that the grasp has all its fingers again within tens of milliseconds. It reads
  the plan in effect through its `plan` port (trajectotree.execution.in_effect).
- `ConeFriction` (`friction`): the friction of the grasp QP's cones, the friction estimate through a
  first-order lag, so that the grasp forces move over tens of milliseconds when the estimate falls.

Both are periodic at ControllerGains.rate_hz and at initialization, and their outputs are the values
their next update stores, computed from their state and inputs now: a controller updating at the same
instant reads this period's value, as when the reflexes were part of it (not the last period's).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import EventStatus, LeafSystem

from trajectotree.config import ControllerGains
from trajectotree.execution.closed_loop import low_pass_step
from trajectotree.execution.fingers import HandKinematics
from trajectotree.execution.in_effect import PlanInEffect, declare_plan_input
from trajectotree.execution.reference import GraspSchedule
from trajectotree.geometry import rotation_2d
from trajectotree.scene.plant import Scene


class LandingReflex(LeafSystem):
    """Input ports `box_state` (6: x, y, theta and their rates in W), `hand_state` (4F: the hand's
    [q; v]), `mu_estimate` (1, the friction estimate), `reflex` (1, the push reflex, 0..1) and `plan`
    (the PlanInEffect: its schedule, and its mu_assumed, which the estimate is compared with).
    Output port `clocks` (F: the schedule sample each finger follows, as floats; see landing_clocks)."""

    def __init__(self, scene: Scene, gains: ControllerGains):
        super().__init__()
        self.gains = gains
        self._kinematics = HandKinematics(scene.fingers, scene.config.gravity)
        self._num_fingers, self._num_joints = scene.num_fingers, scene.num_hand_joints
        self.box_state_port = self.DeclareVectorInputPort("box_state", 6)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * scene.num_hand_joints)
        self.mu_estimate_port = self.DeclareVectorInputPort("mu_estimate", 1)
        self.reflex_port = self.DeclareVectorInputPort("reflex", 1)
        self.plan_port = declare_plan_input(self)
        # At 0 on a fresh run: the schedule's first sample, of the plan of version 0.
        self._clock_state = self.DeclareDiscreteState(np.zeros(scene.num_fingers))
        self._version_state = self.DeclareDiscreteState(np.zeros(1))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self._Update)
        self.DeclareInitializationDiscreteUpdateEvent(self._Update)
        self.clocks_port = self.DeclareVectorOutputPort("clocks", scene.num_fingers, self.CalcClocks)

    def clocks(self, context) -> np.ndarray:
        """The clocks now. On a plan swapped in (a new version) every finger starts again on the schedule's
        own sample: a landing run ahead belonged to the old plan (its samples ahead are the new plan's now;
        followed, they drew a finger along the wrong path)."""
        plan: PlanInEffect = self.plan_port.Eval(context)
        s, n = plan.schedule, plan.schedule.index(context.get_time())
        previous = context.get_discrete_state(self._clock_state).get_value().astype(int)
        if context.get_discrete_state(self._version_state).get_value()[0] != plan.version:
            previous = np.full(self._num_fingers, n)
        box_state, hand_state = self.box_state_port.Eval(context), self.hand_state_port.Eval(context)
        lag = self.path_lag(s, previous, box_state, hand_state)
        wanted = self.landing_triggered(
            float(self.mu_estimate_port.Eval(context)[0]), self.reflex_port.Eval(context)[0], plan.mu_assumed
        )
        return self.landing_clocks(s, n, previous, wanted, lag)

    def CalcClocks(self, context, output):
        output.SetFromVector(self.clocks(context).astype(float))

    def _Update(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._clock_state).SetFromVector(self.clocks(context).astype(float))
        discrete_state.get_mutable_vector(self._version_state).SetFromVector([self.plan_port.Eval(context).version])
        return EventStatus.Succeeded()

    def landing_triggered(self, mu_estimate: float, reflex: float, mu_assumed: float) -> bool:
        """The landing reflex is wanted: a push is on, or the friction estimate fell
        gains.landing_reflex.friction_drop below `mu_assumed`, the plan's (its stances of fewer fingers may slip)."""
        return reflex > 0.0 or mu_estimate < mu_assumed - self.gains.landing_reflex.friction_drop

    def path_lag(self, s: GraspSchedule, clocks, box_state, hand_state) -> np.ndarray:
        """(F,) m, how far each measured fingertip is from its target at its sample `clocks` of `s`."""
        p_WF = self._kinematics(hand_state[: self._num_joints])[0]
        R = rotation_2d(box_state[2])
        clocks = np.minimum(clocks, len(s.X) - 1)
        p_target = box_state[:2] + s.p_BF[clocks, np.arange(self._num_fingers)] @ R.T
        return np.linalg.norm(p_target - p_WF, axis=1)

    def landing_clocks(self, s: GraspSchedule, n: int, previous: np.ndarray, wanted: bool, lag=None) -> np.ndarray:
        """(F,) the sample of `s` each finger follows at plan sample n. The plan's (n), but a
        finger that swings while the landing reflex is `wanted` (or that already runs ahead: a
        landing once begun is finished) runs its swing gains.landing_reflex.speedup x as fast, up to its
        next planned landing, and then holds there until the plan catches up: its box-frame
        path lifted as planned, so that it lands where the plan lands it, only sooner. Its sample waits
        while the fingertip lags its target by more than gains.landing_reflex.lag (`lag` (F,) m, path_lag; None:
        none lags): a target run far ahead drew the finger after it at 3 m/s into the box."""
        clocks = np.minimum(np.maximum(previous, n), len(s.X) - 1)
        if self.gains.landing_reflex.speedup <= 1.0:
            return np.full(self._num_fingers, n)
        g = self.gains
        approach = int(round(g.landing_reflex.approach_time / s.period))
        for i, c in enumerate(clocks):
            landing = s.landing[c, i]
            if landing < 0 or s.force_scale[c, i] >= 1.0:
                continue  # holding (or landed early and waiting), or no landing ahead
            if (wanted or c > n) and (lag is None or lag[i] <= g.landing_reflex.lag):
                # The last land_approach_time of the path slower: at the full speed-up the sphere hit the box
                # 4.5 mm deep with 9 N and knocked the other fingers off.
                speedup = g.landing_reflex.speedup if landing - c > approach else g.landing_reflex.approach_speedup
                clocks[i] = min(max(previous[i], n - 1) + int(round(speedup)), landing)
        return clocks


class ConeFriction(LeafSystem):
    """Input port `mu_estimate` (1); output port `friction` (1): the estimate through a first-order lag
    of time constant gains.grasp.cone_time_constant s (0: none), starting at `mu_assumed`."""

    def __init__(self, gains: ControllerGains, *, mu_assumed: float):
        super().__init__()
        self.gains = gains
        self.mu_estimate_port = self.DeclareVectorInputPort("mu_estimate", 1)
        self._state = self.DeclareDiscreteState(np.array([mu_assumed]))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self._Update)
        self.DeclareInitializationDiscreteUpdateEvent(self._Update)
        self.friction_port = self.DeclareVectorOutputPort("friction", 1, self.CalcFriction)

    def friction(self, context) -> float:
        previous = context.get_discrete_state(self._state).get_value()[0]
        return self.cone_friction(previous, float(self.mu_estimate_port.Eval(context)[0]))

    def CalcFriction(self, context, output):
        output.SetFromVector([self.friction(context)])

    def _Update(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._state).SetFromVector([self.friction(context)])
        return EventStatus.Succeeded()

    def cone_friction(self, previous: float, estimate: float) -> float:
        """The friction of the QP's cones one control period after `previous`: a first-order lag
        towards the friction `estimate`."""
        tau = self.gains.grasp.cone_time_constant
        if tau <= 0.0:
            return estimate
        return low_pass_step(previous, estimate, min(1.0 / (self.gains.rate_hz * tau), 1.0))
