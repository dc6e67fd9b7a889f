"""The search's refusals as values: their sentences, how refused moves are tallied, and plan.json."""

import json
import math

from trajectotree.contact_plan import ContactPlan
from trajectotree.refusal import AtRoot, NoPlan, OnGrids, Recorded, Refusal, RefusalKind, refusal_from_json

CLOSURE = Refusal(RefusalKind.NOT_IN_CLOSURE, mu_plan=0.49, margin=-0.0123, required_mu=0.6698)


def test_every_kind_reads_as_a_sentence():
    examples = {
        RefusalKind.CORNER: (Refusal(RefusalKind.CORNER, limit=0.015), "a contact lies within 0.015 m of a corner"),
        RefusalKind.NOT_IN_CLOSURE: (
            CLOSURE,
            "not in frictional form closure at mu_plan 0.49 (margin -0.0123, needs mu 0.67)",
        ),
        RefusalKind.UNREACHABLE: (
            Refusal(RefusalKind.UNREACHABLE, fingers=(2,), cause=Refusal(RefusalKind.LINKS_PENETRATE)),
            "finger 2 cannot reach its contact: finger links penetrate the box",
        ),
        RefusalKind.STUCK_FINGER_HELD: (
            Refusal(RefusalKind.STUCK_FINGER_HELD, fingers=(0,), stance=(1, 2, 3)),
            "finger 0 must move (out of reach) but is held: stance of fingers (1, 2, 3) not in closure at mu_plan",
        ),
        RefusalKind.TOO_MANY_SWITCHES: (
            Refusal(RefusalKind.TOO_MANY_SWITCHES, count=4, per_finger=(1, 1, 2, 0), limit=2),
            "the goal needs at least 4 contact switches (per finger [1, 1, 2, 0], each finger staying on "
            "reachable contacts), more than the 2 steps of 3 nodes",
        ),
        RefusalKind.INITIAL_GRASP: (
            Refusal(RefusalKind.INITIAL_GRASP, cause=Refusal(RefusalKind.TIPS_OVERLAP)),
            "initial grasp not allowed: two fingertips overlap",
        ),
    }
    for kind, (refusal, text) in examples.items():
        assert refusal.kind is kind and str(refusal) == text
    # an initial grasp refused by its closure is infeasible, not "not allowed"
    assert str(Refusal(RefusalKind.INITIAL_GRASP, cause=CLOSURE)).startswith("initial grasp infeasible: not in")
    numbers = dict(mu_plan=0.49, required_mu=0.5, margin=0.0, limit=2, count=3, subset=1, per_finger=(1, 2, 0, 0))
    for kind in RefusalKind:  # every kind of Refusal has a sentence that names its numbers
        if kind not in (RefusalKind.NO_PLAN, RefusalKind.ON_GRIDS, RefusalKind.RECORDED):
            cause = Refusal(RefusalKind.OUT_OF_REACH)
            text = str(Refusal(kind, fingers=(1,), stance=(0, 2, 3), cause=cause, **numbers))
            assert text and "None" not in text, kind


def test_refused_moves_are_tallied_without_their_measurements():
    other = Refusal(RefusalKind.NOT_IN_CLOSURE, mu_plan=0.49, margin=-0.5, required_mu=0.9)
    assert CLOSURE != other and CLOSURE.coarse() == other.coarse()
    assert str(CLOSURE.coarse()) == "not in frictional form closure at mu_plan 0.49"
    reach = Refusal(RefusalKind.UNREACHABLE, fingers=(2,), cause=Refusal(RefusalKind.OUT_OF_REACH))
    assert str(reach.coarse()) == "finger 2 cannot reach its contact"


def test_a_search_refusal_survives_plan_json():
    root = (0.06, 0.18, 0.32, 0.5)
    no_plan = NoPlan(
        searched=1,
        candidates=3,
        skipped=2,
        first_skipped=AtRoot(root, Refusal(RefusalKind.DEADLINES, fingers=(0, 1), count=1)),
        last_searched=AtRoot(root, Refusal(RefusalKind.TREE_EXHAUSTED, count=12)),
        mu_plan=0.49,
        refused=((CLOSURE.coarse(), 7), (Refusal(RefusalKind.SWITCH_BOUND), 3)),
    )
    grids = OnGrids(
        (
            (0.02, no_plan),
            (0.01, Refusal(RefusalKind.NO_INITIAL_GRASP, mu_plan=0.49, required_mu=math.inf, count=5, subset=2)),
        )
    )
    assert str(grids).startswith("at the 0.02 m contact grid: no plan from 1 searched initial grasp(s) of 3 (2 skipped")
    assert "not in frictional form closure at mu_plan 0.49 x7; too many switches left (bound) x3" in str(grids)
    assert "(best stance needs mu inf)" in str(grids)
    plan = ContactPlan(goal=1.0, success=False, refusal=grids)
    data = json.loads(json.dumps(plan.to_json(), allow_nan=False))  # strict JSON: inf is written as "inf"
    assert data["reason"] == str(grids) and data["refusal"]["kind"] == "on_grids"
    again = ContactPlan.from_json(data)
    assert again.refusal == grids and again.reason == plan.reason
    # a plan.json written before refusals had kinds keeps its text
    del data["refusal"]
    old = ContactPlan.from_json(data)
    assert old.refusal == Recorded(str(grids)) and old.reason == str(grids)
    assert refusal_from_json(None) is None and ContactPlan(goal=0.0, success=True).reason == ""
