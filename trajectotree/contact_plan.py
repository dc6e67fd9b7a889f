"""The contact-sequence planner's output: the value on the arrow from search to CITO.

A `ContactPlan` holds N `ContactNode`s, one per object pose x*_n of the path.
Node n's `switching_finger` is the finger that moved to a new contact between
node n-1 and node n (None when no finger moved, and always for node 0), so
transition segment s = n - 1 has that finger free and the other three fixed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from trajectotree.refusal import SearchRefusal, refusal_from_json


@dataclass(frozen=True)
class ContactNode:
    object_pose: np.ndarray  # (3,) x*_n = (x m, y m, theta rad) in W
    q: np.ndarray  # (8,) rad, joint angles q*_n from IK (finger-major)
    arclengths: np.ndarray  # (4,) m, each finger's contact along the box boundary
    p_BC: np.ndarray  # (4, 2) m, contact points in the box frame B
    n_B: np.ndarray  # (4, 2) outward unit normals at the contacts, in B
    switching_finger: int | None  # finger that moved between node n-1 and node n
    closure_margin: float  # N, the form-closure LP's margin d* at mu_plan (> 0: in form closure)
    # smallest friction coefficient at which the node's four contacts are in frictional form closure
    required_mu: float = float("nan")
    # the same for the three fingers that held the box while switching_finger moved to this node
    # (segment n-1 -> n); None when no finger moved (and for node 0)
    stance_required_mu: float | None = None
    # N, the hardest push along each of +-x and +-y in W that the fingers holding during segment n-1 -> n (all
    # of them when none moved) resist at both of its ends (trajectotree.search.stance.PushCapacityLp at mu_plan);
    # None for node 0, in older files, and when they cannot hold the weight within their bounds at all
    stance_push_capacity: float | None = None

    def to_json(self) -> dict:
        return {
            "object_pose": [float(v) for v in self.object_pose],
            "q": [float(v) for v in self.q],
            "switching_finger": self.switching_finger,
            "closure_margin": float(self.closure_margin),
            "required_mu": _finite_or_none(self.required_mu),
            "stance_required_mu": _finite_or_none(self.stance_required_mu),
            "stance_push_capacity": _finite_or_none(self.stance_push_capacity),
            "contacts": [
                {"arclength": float(s), "p_B": [float(v) for v in p], "n_B": [float(v) for v in n]}
                for s, p, n in zip(self.arclengths, self.p_BC, self.n_B)
            ],
        }

    @staticmethod
    def from_json(data: dict) -> ContactNode:
        contacts = data["contacts"]
        return ContactNode(
            object_pose=np.array(data["object_pose"], dtype=float),
            q=np.array(data["q"], dtype=float),
            arclengths=np.array([c["arclength"] for c in contacts], dtype=float),
            p_BC=np.array([c["p_B"] for c in contacts], dtype=float),
            n_B=np.array([c["n_B"] for c in contacts], dtype=float),
            switching_finger=data["switching_finger"],
            closure_margin=float(data.get("closure_margin", np.nan)),
            required_mu=_float_or_nan(data.get("required_mu")),  # older files lack both keys
            stance_required_mu=_float_or_none(data.get("stance_required_mu")),
            stance_push_capacity=_float_or_none(data.get("stance_push_capacity")),
        )


def _finite_or_none(value) -> float | None:
    """JSON has no nan/inf: unknown or unbounded values are written as null."""
    return None if value is None or not np.isfinite(value) else float(value)


def _float_or_none(value) -> float | None:
    return None if value is None else float(value)


def _float_or_nan(value) -> float:
    return float("nan") if value is None else float(value)


@dataclass(frozen=True)
class SearchStats:
    expanded: int = 0  # nodes popped from the open set
    generated: int = 0  # neighbour nodes inserted into the tree
    lp_calls: int = 0  # form-closure LP solves
    ik_calls: int = 0  # inverse-kinematics solves
    time_s: float = 0.0  # wall-clock search time, s
    initial_grasps_searched: int = 0  # candidate initial grasps the tree search was rooted at
    initial_grasp_candidates: int = 0  # ranked candidate initial grasps (1 when the user gave one)

    def to_json(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class ContactPlan:
    goal: float  # rad, the goal orientation of the object in W
    success: bool  # a path of N nodes reached the goal pose
    refusal: SearchRefusal | None = None  # why not, when success is False (None otherwise)
    nodes: tuple[ContactNode, ...] = ()  # N nodes on success, () otherwise
    stats: SearchStats = field(default_factory=SearchStats)
    mu_plan: float = float("nan")  # friction coefficient the plan was searched with
    goal_position: tuple[float, float] | None = None  # m, the goal position in W; None: the start's

    @property
    def reason(self) -> str:
        """Why the search found no plan, in words ("" when it found one)."""
        return "" if self.refusal is None else str(self.refusal)

    @property
    def object_path(self) -> np.ndarray:
        """(N, 3) the object poses x*_n."""
        return np.array([n.object_pose for n in self.nodes])

    def to_json(self) -> dict:
        return {
            "goal": float(self.goal),
            "goal_position": None if self.goal_position is None else [float(v) for v in self.goal_position],
            "success": self.success,
            "reason": self.reason,
            "refusal": None if self.refusal is None else self.refusal.to_json(),
            "mu_plan": _finite_or_none(self.mu_plan),
            "stats": self.stats.to_json(),
            "contact_sequence": [n.to_json() for n in self.nodes],
        }

    @staticmethod
    def from_json(data: dict) -> ContactPlan:
        return ContactPlan(
            goal=float(data["goal"]),
            success=bool(data["success"]),
            refusal=refusal_from_json(data.get("refusal"), data.get("reason", "")),
            nodes=tuple(ContactNode.from_json(n) for n in data.get("contact_sequence") or ()),
            stats=SearchStats(**data.get("stats", {})),
            mu_plan=_float_or_nan(data.get("mu_plan")),
            goal_position=None if data.get("goal_position") is None else tuple(data["goal_position"]),
        )


# -- in space ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpaceContactNode:
    """Node n of a contact sequence in space: the box's pose, the joint angles and each finger's contact."""

    object_pose: np.ndarray  # (7,) Drake's floating-body positions [qw, qx, qy, qz, px, py, pz] in W
    q: np.ndarray  # (F, n) rad, joint angles from IK
    faces: tuple[str, ...]  # each finger's face of the box (geometry.BOX_FACE_NAMES)
    p_BC: np.ndarray  # (F, 3) m, the contact points in the box frame B
    switching_finger: int | None  # the finger that moved between node n-1 and node n
    closure_margin: float  # the 6-D closure LP's margin d* of the four contacts at mu_plan
    # N m, the largest joint torque with which the fingers holding during segment n-1 -> n (all when none moved)
    # hold the box at rest at both its ends, their own weight included; None for node 0
    stance_torque: float | None = None
    # N (or N m), the hardest push along +-x, +-y, +-z in W that stance resists at node n; None for node 0
    stance_push_capacity: float | None = None
    # whether that stance (node 0: the four fingers' initial grasp) holds the box within the motors with friction
    # cones at the search's stance margin (search.space_stance_margin), not only at mu_plan
    stance_margin: bool = True
    # the least of the search's stance frictions (the margin's, search.space_stance_fallback_safety's, mu_plan) at
    # which that stance holds the box within the motors (space_stance_margin none: mu_plan; nan: a measured grasp
    # that holds at none)
    stance_mu: float = float("nan")

    def to_json(self) -> dict:
        return {
            "object_pose": [float(v) for v in self.object_pose],
            "q": np.asarray(self.q, dtype=float).tolist(),
            "contacts": [
                {"face": face, "p_BC": [float(v) for v in p]} for face, p in zip(self.faces, self.p_BC, strict=True)
            ],
            "switching_finger": self.switching_finger,
            "closure_margin": float(self.closure_margin),
            "stance_torque": self.stance_torque,
            "stance_push_capacity": self.stance_push_capacity,
            "stance_margin": self.stance_margin,
            "stance_mu": _finite_or_none(self.stance_mu),
        }


@dataclass(frozen=True)
class SpaceContactPlan:
    """A contact sequence in space toward a goal orientation, or why none was found."""

    goal: tuple[float, float, float, float]  # the goal orientation, a unit quaternion [w, x, y, z] in W
    success: bool
    refusal: SearchRefusal | None = None
    nodes: tuple[SpaceContactNode, ...] = ()
    stats: SearchStats = field(default_factory=SearchStats)
    mu_plan: float = float("nan")
    max_segment_rotation: float = float("nan")  # rad, the largest rotation between two nodes
    mu_margin: float = float("nan")  # the stances' margin friction (search.space_stance_margin; mu_plan: none)

    @property
    def reason(self) -> str:
        return "" if self.refusal is None else str(self.refusal)

    @property
    def margin_stances(self) -> int:
        """How many of the nodes' stances (the initial grasp's included) hold the box at the margin's friction."""
        return sum(n.stance_margin for n in self.nodes)

    def to_json(self) -> dict:
        return {
            "kind": "space",
            "goal_quaternion": [float(v) for v in self.goal],
            "success": self.success,
            "reason": self.reason,
            "refusal": None if self.refusal is None else self.refusal.to_json(),
            "mu_plan": _finite_or_none(self.mu_plan),
            "max_segment_rotation": _finite_or_none(self.max_segment_rotation),
            "mu_margin": _finite_or_none(self.mu_margin),
            "margin_stances": self.margin_stances,
            "stances": len(self.nodes),
            "stats": self.stats.to_json(),
            "contact_sequence": [n.to_json() for n in self.nodes],
        }
