"""The closed loop's two systems between its estimates and the grasp controller
(trajectotree.execution.control.ClosedLoopGraspController), each its own LeafSystem:

- `LandingReflex` (`clocks`): the schedule sample each finger follows. The plan's, but while the push
  reflex is on or the friction estimate has fallen, a swinging finger runs its planned swing ahead to
  its next landing, so that the grasp has all its fingers again within tens of milliseconds.
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
from trajectotree.execution.reference import GraspSchedule
from trajectotree.geometry import rotation_2d
from trajectotree.scene.plant import Scene


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


class LandingReflex(LeafSystem):
    """Input ports `box_state` (6: x, y, theta and their rates in W), `hand_state` (4F: the hand's
    [q; v]), `mu_estimate` (1, the friction estimate) and `reflex` (1, the push reflex, 0..1).
    Output port `clocks` (F: the schedule sample each finger follows, as floats; see landing_clocks).
    mu_assumed: the friction the plan in effect assumes, which the estimate is compared with."""

    def __init__(self, scene: Scene, schedule: GraspSchedule, gains: ControllerGains, *, mu_assumed: float):
        super().__init__()
        self.gains, self.schedule = gains, schedule
        self._kinematics = HandKinematics(scene.fingers, scene.config.gravity)
        self._num_fingers, self._num_joints = scene.num_fingers, scene.num_hand_joints
        self._mu_assumed = mu_assumed
        self.landing = next_landing(schedule.force_scale)
        self.box_state_port = self.DeclareVectorInputPort("box_state", 6)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * scene.num_hand_joints)
        self.mu_estimate_port = self.DeclareVectorInputPort("mu_estimate", 1)
        self.reflex_port = self.DeclareVectorInputPort("reflex", 1)
        # At 0 on a fresh run: the schedule's first sample (restart sets another run's continuation).
        self._clock_state = self.DeclareDiscreteState(np.zeros(scene.num_fingers))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self._Update)
        self.DeclareInitializationDiscreteUpdateEvent(self._Update)
        self.clocks_port = self.DeclareVectorOutputPort("clocks", scene.num_fingers, self.CalcClocks)

    def restart(self, context) -> None:
        """Every finger back on the schedule's own sample at the context's time: a replanned phase
        carries the last phase's state over, but a landing it ran ahead belonged to the old plan
        (its samples ahead are the new plan's now; followed, they drew a finger along the wrong path)."""
        n = self.schedule.index(context.get_time())
        context.SetDiscreteState(self._clock_state, np.full(self._num_fingers, float(n)))

    def clocks(self, context) -> np.ndarray:
        previous = context.get_discrete_state(self._clock_state).get_value().astype(int)
        box_state, hand_state = self.box_state_port.Eval(context), self.hand_state_port.Eval(context)
        lag = self.path_lag(previous, box_state, hand_state)
        wanted = self.landing_triggered(
            float(self.mu_estimate_port.Eval(context)[0]), self.reflex_port.Eval(context)[0]
        )
        return self.landing_clocks(self.schedule.index(context.get_time()), previous, wanted, lag)

    def CalcClocks(self, context, output):
        output.SetFromVector(self.clocks(context).astype(float))

    def _Update(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._clock_state).SetFromVector(self.clocks(context).astype(float))
        return EventStatus.Succeeded()

    def landing_triggered(self, mu_estimate: float, reflex: float) -> bool:
        """The landing reflex is wanted: a push is on, or the friction estimate fell
        gains.landing_reflex.friction_drop below the plan's (its stances of fewer fingers may slip)."""
        return reflex > 0.0 or mu_estimate < self._mu_assumed - self.gains.landing_reflex.friction_drop

    def path_lag(self, clocks, box_state, hand_state) -> np.ndarray:
        """(F,) m, how far each measured fingertip is from its target at its schedule sample `clocks`."""
        p_WF = self._kinematics(hand_state[: self._num_joints])[0]
        R = rotation_2d(box_state[2])
        clocks = np.minimum(clocks, len(self.schedule.X) - 1)
        p_target = box_state[:2] + self.schedule.p_BF[clocks, np.arange(self._num_fingers)] @ R.T
        return np.linalg.norm(p_target - p_WF, axis=1)

    def landing_clocks(self, n: int, previous: np.ndarray, wanted: bool, lag=None) -> np.ndarray:
        """(F,) the schedule sample each finger follows at plan sample n. The plan's (n), but a
        finger that swings while the landing reflex is `wanted` (or that already runs ahead: a
        landing once begun is finished) runs its swing gains.landing_reflex.speedup x as fast, up to its
        next planned landing, and then holds there until the plan catches up: its box-frame
        path lifted as planned, so that it lands where the plan lands it, only sooner. Its sample waits
        while the fingertip lags its target by more than gains.landing_reflex.lag (`lag` (F,) m, path_lag; None:
        none lags): a target run far ahead drew the finger after it at 3 m/s into the box."""
        clocks = np.minimum(np.maximum(previous, n), len(self.schedule.X) - 1)
        if self.gains.landing_reflex.speedup <= 1.0:
            return np.full(self._num_fingers, n)
        g = self.gains
        approach = int(round(g.landing_reflex.approach_time / self.schedule.period))
        for i, c in enumerate(clocks):
            landing = self.landing[c, i]
            if landing < 0 or self.schedule.force_scale[c, i] >= 1.0:
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
