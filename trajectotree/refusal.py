"""Why the contact-sequence search refused something, as values: a node, a move, an initial
grasp, a whole tree or a whole contact grid (trajectotree.search).

A `Refusal` is one check's answer: its `kind` and the numbers the check found (the fingers and
stance concerned, the friction they need, the bound they exceed); `str()` gives the sentence a
person reads. A search that finds no plan ends in a `NoPlan` (the initial grasps it tried and the
moves it refused most often) or, over several contact grids, in `OnGrids`. Code decides by the
kind and the numbers, never by the text; plan.json keeps both (`to_json`, `refusal_from_json`).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace


class RefusalKind(enum.Enum):
    # a node, or an initial grasp, is not allowed
    CORNER = "corner"  # a contact within `limit` m (scene.corner_margin) of a corner
    TIPS_OVERLAP = "tips_overlap"  # two fingertip spheres overlap
    # a node is a dead end (IsFeasible)
    NOT_IN_CLOSURE = "not_in_closure"  # not in frictional form closure at mu_plan
    UNREACHABLE = "unreachable"  # finger `fingers[0]` cannot reach its contact; `cause` says why
    OUT_OF_REACH = "out_of_reach"  # (a reach cause) no joint angles within the limits
    LINKS_PENETRATE = "links_penetrate"  # (a reach cause) every solution has a link in the object
    IK_FAILED = "ik_failed"  # (a reach cause) Drake's IK did not converge
    # `fingers` (two) come within `limit` m (search.finger_clearance) of each other at the node, or on the
    # straight joint-space path to it from its parent (`count` 1); in space, at a stance
    FINGERS_COLLIDE = "fingers_collide"
    # a move is not generated (GetNeighbors)
    CONTACTS_LOST = "contacts_lost"  # two or more `fingers` leave reach at the next pose
    FINGER_HELD = "finger_held"  # `fingers[0]` may not let go: the other three (`stance`) not in closure
    STUCK_FINGER_HELD = "stuck_finger_held"  # the same for a finger that must move (its contact leaves reach)
    NEW_CONTACT_UNREACHABLE = "new_contact_unreachable"  # `fingers[0]`'s new contact: out of reach or at a corner
    SWITCH_BOUND = "switch_bound"  # more contact switches left than steps (search.switch_bound)
    STANCE_ROLLS_OFF = "stance_rolls_off"  # a holding fingertip of `stance` rolls off its face or within `limit` m
    # (search.rolled_corner_gap) of a corner
    STANCE_ROLLED_OPEN = "stance_rolled_open"  # `stance` not in closure at mu_plan where its tips roll to
    STANCE_TOO_HEAVY = "stance_too_heavy"  # `stance` needs more than `limit` N to hold the weight
    STANCE_OVER_MOTORS = "stance_over_motors"  # (in space) `stance` needs more than `limit` N m at a joint to hold
    # an initial grasp is skipped before its tree is searched
    INITIAL_GRASP = "initial_grasp"  # the grasp itself: `cause`
    NO_PATH_CONTACTS = "no_path_contacts"  # `fingers` have no reachable corner-free contact at some node
    TOO_MANY_SWITCHES = "too_many_switches"  # `count` switches (`per_finger`) for `limit` steps
    DEADLINES = "deadlines"  # `fingers` all lose their initial contacts by node `count`
    # no initial grasp at all (search.initial_grasp)
    NO_GRID_CONTACT = "no_grid_contact"  # `fingers` reach no corner-free grid contact at the initial pose
    NO_INITIAL_GRASP = "no_initial_grasp"  # of `count` grid grasps (`subset` apart) no stance holds
    NO_ROOT_PASSES = "no_root_passes"  # none of `count` initial grasps passes the checks; the first: `cause`
    INITIAL_OUT_OF_REACH = "initial_out_of_reach"  # the chosen initial grasp has no closed-form IK
    # one tree from one initial grasp
    NODE_BUDGET = "node_budget"  # `count` expansions spent
    TIME_BUDGET = "time_budget"  # `limit` s spent
    TREE_EXHAUSTED = "tree_exhausted"  # every node of the tree after `count` expansions
    # a whole search (NoPlan, OnGrids) and a reason read from a file without a kind (Recorded)
    NO_PLAN = "no_plan"
    ON_GRIDS = "on_grids"
    RECORDED = "recorded"


_NOT_ALLOWED = (RefusalKind.CORNER, RefusalKind.TIPS_OVERLAP)  # an initial grasp with these is "not allowed"


@dataclass(frozen=True)
class Refusal:
    """One check's refusal; each kind uses the fields its comment in RefusalKind names."""

    kind: RefusalKind
    fingers: tuple[int, ...] = ()  # the finger(s) concerned
    stance: tuple[int, ...] = ()  # the three fingers holding the object
    mu_plan: float | None = None  # the friction coefficient the check used
    required_mu: float | None = None  # the least friction the contacts need
    margin: float | None = None  # N, the closure LP's margin d*
    limit: float | None = None  # the bound not met: m, N, s, expansions or steps (per kind)
    count: int | None = None  # expansions made, switches needed, a node, grasps (per kind)
    subset: int | None = None  # of `count`, those with the fingers apart (NO_INITIAL_GRASP)
    per_finger: tuple[int, ...] = ()  # contact switches each finger needs (TOO_MANY_SWITCHES)
    cause: Refusal | None = None  # the refusal underneath (a finger's reach, the initial grasp's)

    def coarse(self) -> Refusal:
        """This refusal without what it measured (margin, required mu, counts, cause), keeping
        the settings it was checked against (mu_plan, limit): how the search tallies refused moves."""
        return replace(self, required_mu=None, margin=None, count=None, subset=None, per_finger=(), cause=None)

    def __str__(self) -> str:
        return _TEXT[self.kind](self)

    def to_json(self) -> dict:
        out = {"kind": self.kind.value}
        for name in ("fingers", "stance", "per_finger"):
            if getattr(self, name):
                out[name] = list(getattr(self, name))
        for name in ("mu_plan", "required_mu", "margin", "limit"):
            if getattr(self, name) is not None:
                out[name] = _number_to_json(getattr(self, name))
        for name in ("count", "subset"):
            if getattr(self, name) is not None:
                out[name] = int(getattr(self, name))
        if self.cause is not None:
            out["cause"] = self.cause.to_json()
        return out


def _closure(r: Refusal) -> str:
    text = "not in frictional form closure"
    if r.mu_plan is not None:
        text += f" at mu_plan {r.mu_plan:.3g}"
    if r.margin is not None and r.required_mu is not None:
        text += f" (margin {r.margin:.3g}, needs mu {r.required_mu:.3g})"
    return text


def _caused(r: Refusal, text: str) -> str:
    return f"{text}: {r.cause}" if r.cause is not None else text


def _stance(r: Refusal) -> str:
    return f"stance of fingers {r.stance}"


def _finger(r: Refusal) -> str:
    return f"finger {r.fingers[0]}" if r.fingers else "a finger"


_TEXT = {
    RefusalKind.CORNER: lambda r: f"a contact lies within {r.limit} m of a corner",
    RefusalKind.TIPS_OVERLAP: lambda r: "two fingertips overlap",
    RefusalKind.NOT_IN_CLOSURE: _closure,
    RefusalKind.UNREACHABLE: lambda r: _caused(r, f"{_finger(r)} cannot reach its contact"),
    RefusalKind.OUT_OF_REACH: lambda r: "out of reach within joint limits",
    RefusalKind.LINKS_PENETRATE: lambda r: "finger links penetrate the box",
    RefusalKind.IK_FAILED: lambda r: "inverse kinematics failed",
    RefusalKind.FINGERS_COLLIDE: lambda r: (
        f"fingers {list(r.fingers)} come within {r.limit:g} m of each other"
        + (" on the way from the previous node" if r.count else "")
    ),
    RefusalKind.CONTACTS_LOST: lambda r: (
        f"fingers {list(r.fingers)} lose their contacts (out of reach) at the same node"
    ),
    RefusalKind.FINGER_HELD: lambda r: f"{_finger(r)} held: {_stance(r)} not in closure at mu_plan",
    RefusalKind.STUCK_FINGER_HELD: (
        lambda r: f"{_finger(r)} must move (out of reach) but is held: {_stance(r)} not in closure at mu_plan"
    ),
    RefusalKind.NEW_CONTACT_UNREACHABLE: lambda r: f"{_finger(r)} new contact out of reach or at a corner",
    RefusalKind.SWITCH_BOUND: lambda r: "too many switches left (bound)",
    RefusalKind.STANCE_ROLLS_OFF: lambda r: (
        f"{_stance(r)} rolls off a face" + ("" if r.limit is None else f" or to within {r.limit:g} m of a corner")
    ),
    RefusalKind.STANCE_ROLLED_OPEN: lambda r: f"{_stance(r)} not in closure at mu_plan at its rolled contacts",
    RefusalKind.STANCE_TOO_HEAVY: lambda r: f"{_stance(r)} needs more than {r.limit:g} N to hold the object's weight",
    RefusalKind.STANCE_OVER_MOTORS: lambda r: (
        f"{_stance(r)} needs more than {r.limit:g} N m at a joint (search.space_torque_fraction of the motors' limit) "
        "to hold the object (their own weight included)"
    ),
    RefusalKind.INITIAL_GRASP: lambda r: _caused(
        r, f"initial grasp {'not allowed' if r.cause and r.cause.kind in _NOT_ALLOWED else 'infeasible'}"
    ),
    RefusalKind.NO_PATH_CONTACTS: (
        lambda r: (
            f"finger(s) {list(r.fingers)} have no reachable, corner-free contacts at every node of the object path"
        )
    ),
    RefusalKind.TOO_MANY_SWITCHES: (
        lambda r: (
            f"the goal needs at least {r.count} contact switches (per finger {list(r.per_finger)}, each "
            f"finger staying on reachable contacts), more than the {int(r.limit)} steps of {int(r.limit) + 1} nodes"
        )
    ),
    RefusalKind.DEADLINES: (
        lambda r: (
            f"fingers {list(r.fingers)} all lose their initial contacts (out of reach) by node {r.count}, "
            "but only one finger can switch per node"
        )
    ),
    RefusalKind.NO_GRID_CONTACT: (
        lambda r: f"finger(s) {list(r.fingers)} reach no corner-free contact at the initial pose"
    ),
    RefusalKind.NO_INITIAL_GRASP: (
        lambda r: (
            f"no initial grasp: of {r.count} reachable grid grasps ({r.subset} with the fingers "
            f"apart) none has a three-finger stance in frictional form closure at mu_plan {r.mu_plan:.3g} "
            f"(best stance needs mu {r.required_mu:.3g})"
        )
    ),
    RefusalKind.NO_ROOT_PASSES: (
        lambda r: f"no initial grasp passes the checks for this goal (of {r.count}; first: {r.cause})"
    ),
    RefusalKind.INITIAL_OUT_OF_REACH: lambda r: "initial grasp out of reach of the fingers",
    RefusalKind.NODE_BUDGET: lambda r: f"node budget exhausted ({r.count} expansions)",
    RefusalKind.TIME_BUDGET: lambda r: f"time budget exhausted ({r.limit} s)",
    RefusalKind.TREE_EXHAUSTED: lambda r: f"tree exhausted after {r.count} expansions",
}


@dataclass(frozen=True)
class AtRoot:
    """A refusal concerning one initial grasp (its contacts' arclengths, m)."""

    root: tuple[float, ...]
    refusal: Refusal

    def __str__(self) -> str:
        return f"{self.root}: {self.refusal}"

    def to_json(self) -> dict:
        return {"root": list(self.root), "refusal": self.refusal.to_json()}

    @staticmethod
    def from_json(data: dict | None) -> AtRoot | None:
        return None if data is None else AtRoot(tuple(data["root"]), _refusal(data["refusal"]))


@dataclass(frozen=True)
class NoPlan:
    """Why one contact grid's search found no plan from its initial grasps."""

    searched: int  # initial grasps whose tree was searched
    candidates: int  # initial grasps ranked
    skipped: int  # initial grasps skipped by the cheap checks
    first_skipped: AtRoot | None  # the first skipped one and why
    last_searched: AtRoot | None  # the last searched one and how its tree ended
    mu_plan: float
    refused: tuple[tuple[Refusal, int], ...]  # the most frequent refused moves (coarse) and their counts

    kind = RefusalKind.NO_PLAN

    def __str__(self) -> str:
        moves = "; ".join(f"{why} x{n}" for why, n in self.refused) or "none"
        return (
            f"no plan from {self.searched} searched initial grasp(s) of {self.candidates} "
            f"({self.skipped} skipped by cheap checks, first: {self.first_skipped or 'none'}); "
            f"last searched {self.last_searched or 'none'}; moves refused (mu_plan {self.mu_plan:.3g}): {moves}"
        )

    def to_json(self) -> dict:
        return {
            "kind": self.kind.value,
            "searched": self.searched,
            "candidates": self.candidates,
            "skipped": self.skipped,
            "first_skipped": None if self.first_skipped is None else self.first_skipped.to_json(),
            "last_searched": None if self.last_searched is None else self.last_searched.to_json(),
            "mu_plan": _number_to_json(self.mu_plan),
            "refused": [{"refusal": why.to_json(), "count": n} for why, n in self.refused],
        }


@dataclass(frozen=True)
class OnGrids:
    """Why the search found no plan on any of its contact grids, coarsest first."""

    grids: tuple[tuple[float, SearchRefusal], ...]  # (m, the grid's displacement step; its refusal)

    kind = RefusalKind.ON_GRIDS

    def __str__(self) -> str:
        return "; ".join(f"at the {step:g} m contact grid: {why}" for step, why in self.grids)

    def to_json(self) -> dict:
        return {
            "kind": self.kind.value,
            "grids": [{"step": step, "refusal": why.to_json()} for step, why in self.grids],
        }


@dataclass(frozen=True)
class Recorded:
    """A reason read from a plan.json written before reasons had kinds: its text alone."""

    text: str

    kind = RefusalKind.RECORDED

    def __str__(self) -> str:
        return self.text

    def to_json(self) -> dict:
        return {"kind": self.kind.value, "text": self.text}


SearchRefusal = Refusal | NoPlan | OnGrids | Recorded


def on_grids(grids: list[tuple[float, SearchRefusal]]) -> SearchRefusal:
    """The refusal of a search over `grids` (step, refusal): the one grid's own, or OnGrids."""
    return grids[0][1] if len(grids) == 1 else OnGrids(tuple(grids))


def _number_to_json(value: float) -> float | str:
    """JSON has no inf or nan: those are written as the strings float() reads back."""
    return float(value) if math.isfinite(value) else str(float(value))


def _refusal(data: dict) -> Refusal:
    fields = {k: v for k, v in data.items() if k not in ("kind", "cause")}
    for name in ("fingers", "stance", "per_finger"):
        if name in fields:
            fields[name] = tuple(fields[name])
    for name in ("mu_plan", "required_mu", "margin", "limit"):
        if name in fields:
            fields[name] = float(fields[name])
    cause = data.get("cause")
    return Refusal(RefusalKind(data["kind"]), cause=None if cause is None else _refusal(cause), **fields)


def refusal_from_json(data: dict | None, text: str = "") -> SearchRefusal | None:
    """The refusal `to_json` wrote; a file without one but with a reason `text` gives Recorded."""
    if data is None:
        return Recorded(text) if text else None
    kind = RefusalKind(data["kind"])
    if kind is RefusalKind.NO_PLAN:
        return NoPlan(
            searched=data["searched"],
            candidates=data["candidates"],
            skipped=data["skipped"],
            first_skipped=AtRoot.from_json(data["first_skipped"]),
            last_searched=AtRoot.from_json(data["last_searched"]),
            mu_plan=float(data["mu_plan"]),
            refused=tuple((_refusal(r["refusal"]), r["count"]) for r in data["refused"]),
        )
    if kind is RefusalKind.ON_GRIDS:
        return OnGrids(tuple((g["step"], refusal_from_json(g["refusal"])) for g in data["grids"]))
    if kind is RefusalKind.RECORDED:
        return Recorded(data["text"])
    return _refusal(data)
