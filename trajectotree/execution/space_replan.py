"""Replanning a plan in space during its execution (executor grasp-replan): `SpacePlanning`, the space side of the
one Replanner (trajectotree.execution.replan): the planner in space (planning.spatial.plan_space, from the measured
state: start.SpaceStartState), the cube's state and tracking error as the closed loop in space gives them, and the
edits of a SpaceReference a replan makes (the hold while the planner runs, the new plan's segments as scheduled).

A plan in space takes 5-30 s to compute (its search, then every segment at once on the segment pool), far more
than a segment lasts (cito.spatial: SPACE_INTERVALS x SPACE_DT, 1 s): a new plan from the next node would always
come after the hand reached it (ReplanOutcome.LATE). So a replan in space always plans from the measured state,
the hand holding at the node while the planner runs (the simulated world holds that grasp for the measured
compute time), within controller.replan.space_search_deadline_s for its search and space_plan_deadline_s for the
whole plan; all its segments are ready together, when the plan is.

The reference's orientation is not interpolated between knots but integrated from the velocities
(SpaceReference.motion_at), so the hold moves the planned state to the measured one in one step at the switch
(the plane ramps it over replan.HOLD_RAMP): the object feedback's error there drops to zero, the forces stay.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from trajectotree.cito.spatial import SPACE_INTERVALS
from trajectotree.config import Config, SceneConfig
from trajectotree.execution.in_effect import PlanInEffect
from trajectotree.execution.replan import Deadlines, Solved, schedule_rows
from trajectotree.execution.space_control import SpaceReference, space_plan_in_effect
from trajectotree.planning.spatial import SpacePlanResult, plan_space
from trajectotree.scene.spatial import SpaceScene, build_space_scene
from trajectotree.start import SpaceStartState

# The knot arrays of a SpaceReference besides t, and those that are velocities (zero while the hand holds).
KNOT_ARRAYS = ("x", "v", "q", "f_W", "p_W_C", "p_W_tip")


def space_off_plan(error) -> tuple[float, float]:
    """(rad, m) off the planned pose, of the closed loop in space's tracking error (6: the rotation vector rad
    and the offset m from the planned pose to the measured one)."""
    return float(np.linalg.norm(error[:3])), float(np.linalg.norm(error[3:]))


def rows(reference: SpaceReference, index, t) -> dict[str, np.ndarray]:
    """The knots `index` of `reference` at the times `t`."""
    return {"t": np.asarray(t, dtype=float), **{name: getattr(reference, name)[index] for name in KNOT_ARRAYS}}


def at_rest(reference: SpaceReference, times) -> dict[str, np.ndarray]:
    """`reference`'s state at each of `times` (s), held at rest: the planned pose, the joints, forces, contacts
    and fingertips linear between knots, zero velocities."""
    times = np.asarray(times, dtype=float)
    pose = reference.pose_at(times)

    def linear(values: np.ndarray) -> np.ndarray:
        flat = values.reshape(len(reference.t), -1)
        columns = [np.interp(times, reference.t, flat[:, j]) for j in range(flat.shape[1])]
        return np.stack(columns, axis=-1).reshape((len(times),) + values.shape[1:])

    arrays = {name: linear(getattr(reference, name)) for name in ("q", "f_W", "p_W_C", "p_W_tip")}
    return {"t": times, "x": pose, "v": np.zeros((len(times), 6)), **arrays}


def joined_rows(*parts: dict[str, np.ndarray]) -> SpaceReference:
    """One reference of the parts' knots, one after another."""
    return SpaceReference(**{name: np.concatenate([p[name] for p in parts]) for name in ("t", *KNOT_ARRAYS)})


def before(reference: SpaceReference, t: float) -> dict[str, np.ndarray]:
    keep = np.flatnonzero(reference.t < t - 1e-9)
    return rows(reference, keep, reference.t[keep])


def space_delayed(reference: SpaceReference, t_switch: float, delay: float) -> SpaceReference:
    """`reference` holding its state at `t_switch` (a node: at rest) for `delay` s, then going on as before."""
    if delay <= 1e-9:
        return reference
    after = np.flatnonzero(reference.t > t_switch + 1e-9)
    held = at_rest(reference, [t_switch, t_switch])
    held["t"] = np.array([t_switch, t_switch + delay])
    return joined_rows(before(reference, t_switch), held, rows(reference, after, reference.t[after] + delay))


def space_spliced(old: SpaceReference, t_switch: float, new: SpaceReference, t_new: float) -> SpaceReference:
    """`old` up to `t_switch`, then a hold of `new`'s first state (the measured one, its joints refined onto the
    contacts) at rest until `t_new`, then `new` shifted to begin at `t_new`."""
    hold = rows(new, [0], [t_switch])
    hold["v"] = np.zeros((1, 6))
    return joined_rows(before(old, t_switch), hold, rows(new, np.arange(len(new.t)), t_new + new.t - new.t[0]))


def space_scheduled(
    new: SpaceReference, knots_per_segment: int, ready: list[float]
) -> tuple[SpaceReference, np.ndarray]:
    """`new` as executed when its segment k may begin no earlier than ready[k] s after segment 0 begins
    (replan.schedule_rows: a node held, at rest, until its segment is ready). Also the times the nodes are
    reached."""
    index, times, arrivals = schedule_rows(new.t, knots_per_segment, ready)
    return joined_rows(rows(new, index, times)), arrivals


@dataclass(frozen=True, eq=False)
class SpacePlanning:
    """The Replanner's planner and plan in space (module doc): the plan `reference` (its first plan) to the unit
    quaternion `goal` [w, x, y, z], executed with `config` in `scene` (its hand and cube, the plan's), a new plan's
    segments on `segment_workers` local processes (None: planning.spatial.solve_space_segments' default). Its
    object state is the cube's floating joint's (13: [qw qx qy qz px py pz] and [w_W v_W]), its tracking error 6."""

    goal: tuple[float, float, float, float]
    reference: SpaceReference
    config: Config
    scene: SpaceScene
    segment_workers: int | None

    box_state_size = 13
    tracking_error_size = 6
    always_holds = True  # a plan in space takes longer than a segment lasts (module doc)
    off_plan = staticmethod(space_off_plan)
    delayed = staticmethod(space_delayed)

    @property
    def num_joints(self) -> int:
        return sum(len(f.q_lower) for f in self.scene.fingers)

    @property
    def num_fingers(self) -> int:
        return self.scene.num_fingers

    def first_assumed(self) -> SceneConfig:
        """The scene the first plan assumed: its friction and the cube's mass (config.scene.box_mass is the
        plane's box)."""
        return dataclasses.replace(self.config.scene, box_mass=self.scene.object.mass)

    def node_times(self) -> np.ndarray:
        """s, the first plan's nodes (a segment every SPACE_INTERVALS knots)."""
        return self.reference.t[::SPACE_INTERVALS]

    def deadlines(self) -> Deadlines:
        rules = self.config.controller.replan
        return Deadlines(rules.space_search_deadline_s, rules.space_plan_deadline_s)

    def measured_start(self, box, hand) -> SpaceStartState:
        return SpaceStartState(
            object_pose=tuple(box[:7]), q=tuple(hand[: self.num_joints]), object_velocity=tuple(box[7:])
        )

    def solve(self, start: SpaceStartState, mu: float, mass: float, deadlines: Deadlines) -> Solved:
        """Plans in space from `start` to the goal with friction `mu` and the cube's mass `mass` kg, the search
        within deadlines.search_s (wall clock); the segments are ready when all are, a plan later than
        deadlines.first_segment_s (the whole plan's deadline here) is late; StartRefused for a start it cannot
        plan from (planning.start.space_start_root)."""
        cube = self.scene.object
        scene_config = dataclasses.replace(self.config.scene, mu=mu, box_mass=mass)
        assumed = dataclasses.replace(
            self.config,
            scene=scene_config,
            search=dataclasses.replace(self.config.search, space_time_budget_s=deadlines.search_s, budget_clock="wall"),
        )
        # the executed hand (its model file), whatever the config names: the plan's scene is the one executed
        hand = self.scene.hand_file.source
        scene = build_space_scene(hand, mu=mu, gravity=self.scene.gravity, size=tuple(cube.size), mass=mass)
        t0 = time.perf_counter()
        new = plan_space(scene, self.goal, assumed, self.segment_workers, start)
        total = time.perf_counter() - t0
        late = total > deadlines.first_segment_s
        # the joint formulation is one program (reported once): none of a failed one is executed
        joint = new.formulation == "joint"
        count = max(len(new.contact_plan.nodes) - 1, 1)
        solved = [new.trajectory is not None] * count if joint else [bool(s["success"]) for s in new.segments]
        ready = tuple(total if ok and not late else np.inf for ok in solved)
        return Solved(new, ready, late, not joint, scene_config)

    def knots_per_segment(self, new: SpacePlanResult) -> int:
        return SPACE_INTERVALS

    def reference_of(self, arrays: dict) -> SpaceReference:
        return SpaceReference.from_arrays(arrays)

    def in_effect(self, reference: SpaceReference, mu: float, version: int) -> PlanInEffect:
        return space_plan_in_effect(reference, self.config, self.scene, mu_assumed=mu, version=version)

    scheduled = staticmethod(space_scheduled)

    def spliced(self, old, t_switch: float, start, new: SpaceReference, t_new: float) -> SpaceReference:
        return space_spliced(old, t_switch, new, t_new)
