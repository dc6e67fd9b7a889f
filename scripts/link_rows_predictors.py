"""Issue 35 item 1's data: which keyframes segments need the link rows (their first solve, without
them, left a link in the object and was solved again as "links"), beside cheap predictors computed
before solving from the search's nodes and the segment's guess; prints each predictor's confusion
table at a few thresholds (m).

    python scripts/link_rows_predictors.py --goal-list-file /tmp/g35/goals76.txt

Predictors, each a largest depth (m) of a link inside the object at the segment's free knots:
guess (the program's plan_guess, physics.link_penetrations), straight (the straight joint-space path
between the two nodes at the rest-to-rest interpolated object pose), at_start (that path with the
object held at the first node's pose).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from trajectotree.cito.guess import plan_guess, rest_to_rest_progress
from trajectotree.cito.knot import BodyParams, KnotRows
from trajectotree.cito.transition import piece_spec
from trajectotree.config import Config, mu_plan
from trajectotree.planning.physics import link_penetrations
from trajectotree.planning.piece import straight_path_link_depths
from trajectotree.planning.planners import plan
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables

THRESHOLDS = (0.0, 0.005, 0.01, 0.015, 0.02)  # m


def predictors(contact_plan, s: int, scene, body, config: Config) -> dict[str, float]:
    """Segment s's predictors (m), from its nodes and its program's guess only."""
    n0, n1 = contact_plan.nodes[s], contact_plan.nodes[s + 1]
    spec = piece_spec(contact_plan, s, s + 1, radius=scene.tip_radius, config=config.cito)
    sub = dataclasses.replace(contact_plan, nodes=contact_plan.nodes[s : s + 2])
    guess = plan_guess(KnotRows(body, spec.pinned, spec.c_B, spec.n_B), spec, sub)
    u = rest_to_rest_progress(spec.segment_length)
    q = n0.q + np.outer(u, n1.q - n0.q)
    x = n0.object_pose + np.outer(u, n1.object_pose - n0.object_pose)
    shape = config.scene.shape
    return {
        "guess": float(link_penetrations(guess.x, guess.q, scene.fingers, shape)[1:-1].max()),
        "straight": float(link_penetrations(x, q, scene.fingers, shape)[1:-1].max()),
        "at_start": float(straight_path_link_depths(n0, n1, spec.segment_length, scene).max()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal-list-file", required=True, help="goals (rad), whitespace-separated")
    args = parser.parse_args()
    goals = [float(g) for g in open(args.goal_list_file).read().split()]
    config = Config()
    # the first solves without rows, as before cito.link_rows_predicted: which segments then need the links retry
    unpredicted = dataclasses.replace(config, cito=dataclasses.replace(config.cito, link_rows_predicted=False))
    scene, tables = build_scene(config.scene), GraspTables()
    body = BodyParams(scene, config.cito.sdf_sharpness, mu=mu_plan(config.scene, config.search))
    need, values = [], []
    for goal in goals:
        result = plan(goal=goal, config=unpredicted, scene=scene, segment_workers=1, grasp_tables=tables)
        for s, record in enumerate(result.segments):
            need.append(any(a["kind"] == "links" for a in record["attempts"]))
            values.append(predictors(result.contact_plan, s, scene, body, config))
    need = np.array(need)
    print(f"{len(need)} segments of {len(goals)} goals, {int(need.sum())} needed the link rows")
    for name in values[0]:
        v = np.array([row[name] for row in values])
        for t in THRESHOLDS:
            flag = v > t
            print(
                f"{name} > {t * 1e3:g} mm: need and flagged {int((need & flag).sum())}, need and missed "
                f"{int((need & ~flag).sum())}, flagged without need {int((~need & flag).sum())} of {int((~need).sum())}"
            )


if __name__ == "__main__":
    main()
