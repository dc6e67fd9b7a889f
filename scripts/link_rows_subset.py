"""Issue 35 item 1, second try: what a first solve with the link rows of the flagged fingers only costs.
A segment is flagged where the straight joint path between its nodes, with the object held at the first
node's pose, puts a finger's link inside the object (scripts/link_rows_predictors.py's "at_start", the
only predictor that caught all 41 segments needing the rows on the 76 goals); its flagged fingers are
those whose links that path puts inside. Each chosen segment's program is solved alone four ways:
(a) without the link rows (the first solve before), (b) with every finger's rows (the "links" retry),
(c) with the flagged fingers' rows only, (d) with the rows of piece.predicted_link_fingers (the flagged
fingers and those within NEAR_NODE_M of the object at a node: cito.link_rows_predicted's first solve).
For each: IPOPT iterations, build + solve time (s), the physics check passed, whether a link or finger
still overlaps (it would need the "links" retry), and the fingers with a link inside.

    python scripts/link_rows_subset.py --goal-list-file goals.txt --per-class 12
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
from pathlib import Path

import numpy as np

from trajectotree.cito.transition import piece_spec
from trajectotree.config import Config, mu_plan
from trajectotree.planning.physics import link_penetrations
from trajectotree.planning.piece import (
    PieceTask,
    overlaps,
    predicted_link_fingers,
    solve_piece,
    straight_path_link_depths,
)
from trajectotree.planning.planners import plan
from trajectotree.results import LINK_PENETRATION_TOL
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables


def flagged_fingers(contact_plan, s: int, scene, config: Config) -> tuple[int, ...]:
    """The fingers whose links the straight joint path of segment s, object at node s's pose, puts inside."""
    spec = piece_spec(contact_plan, s, s + 1, radius=scene.tip_radius, config=config.cito)
    nodes = contact_plan.nodes[s], contact_plan.nodes[s + 1]
    depth = straight_path_link_depths(*nodes, spec.segment_length, scene)
    return tuple(int(i) for i in np.flatnonzero(depth.max(axis=(0, 2)) > 0.0))


def solve_way(config: Config, mu: float, contact_plan, s: int, way: str, fingers, scene) -> dict:
    cito = dataclasses.replace(config.cito, link_rows=way != "a", link_rows_on_demand=False)
    kind = "links" if way == "b" else "keyframes"
    # d: the package's prediction (the path's fingers and those within NEAR_NODE_M of the object at a node)
    plain = PieceTask(config.scene, config.cito, mu, contact_plan, s, s + 1, "keyframes")
    subset = {"c": fingers, "d": predicted_link_fingers(plain, scene)}
    task = PieceTask(config.scene, cito, mu, contact_plan, s, s + 1, kind, link_fingers=subset.get(way))
    r = solve_piece(task, scene)
    return {
        "it": r.iterations,
        "t": r.build_time_s + r.solve_time_s,
        "pass": r.success,
        "overlap": overlaps(r.check),
        "link_mm": r.check.link_penetration_m * 1e3,
        "inside": inside_fingers(r.trajectory, scene, config),
    }


def inside_fingers(arrays, scene, config: Config) -> tuple[int, ...]:
    """The fingers with a link more than the physics check's tolerance inside the object."""
    depth = link_penetrations(arrays.x, arrays.q, scene.fingers, config.scene.shape)
    return tuple(int(i) for i in np.flatnonzero(depth.max(axis=(0, 2)) > LINK_PENETRATION_TOL))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal-list-file", required=True)
    parser.add_argument("--per-class", type=int, default=12)
    parser.add_argument("--cache", help="a pickle of the flagged segments: written after planning, read instead of it")
    args = parser.parse_args()
    goals = [float(g) for g in open(args.goal_list_file).read().split()]
    config = Config()
    # the first solves without rows, as before cito.link_rows_predicted: which segments then need the links retry
    unpredicted = dataclasses.replace(config, cito=dataclasses.replace(config.cito, link_rows_predicted=False))
    scene, tables = build_scene(config.scene), GraspTables()
    mu = mu_plan(config.scene, config.search)
    rows = []
    cache = Path(args.cache) if args.cache else None
    if cache is not None and cache.exists():
        rows = pickle.loads(cache.read_bytes())
        goals = []
    for goal in goals:
        result = plan(goal=goal, config=unpredicted, scene=scene, segment_workers=1, grasp_tables=tables)
        for s, record in enumerate(result.segments):
            need = any(a["kind"] == "links" for a in record["attempts"])
            fingers = flagged_fingers(result.contact_plan, s, scene, config)
            if fingers:
                rows.append((goal, s, need, fingers, result.contact_plan))
        print(f"goal {goal:+.3f}: {len(result.segments)} segments, flagged so far {len(rows)}", flush=True)
    if cache is not None:
        cache.write_bytes(pickle.dumps(rows))
    print(f"flagged {len(rows)}, of which need {sum(r[2] for r in rows)}")
    rng = np.random.default_rng(0)
    chosen = []
    for need in (True, False):
        group = [r for r in rows if r[2] == need]
        picks = rng.choice(len(group), size=min(args.per_class, len(group)), replace=False)
        chosen += [group[i] for i in sorted(picks)]
    print("goal seg need fingers | a: it t pass ovl mm | b: it t pass ovl mm | c: it t pass ovl mm")
    totals = {}
    for goal, s, need, fingers, cp in chosen:
        out = {w: solve_way(config, mu, cp, s, w, fingers, scene) for w in "abcd"}
        for w, o in out.items():
            tot = totals.setdefault((need, w), [0, 0.0, 0, 0])
            tot[0] += o["it"]
            tot[1] += o["t"]
            tot[2] += o["pass"]
            tot[3] += o["overlap"]
        cells = " | ".join(
            f"{w}: {o['it']} {o['t']:.2f} {int(o['pass'])} {int(o['overlap'])} {o['link_mm']:.1f} {o['inside']}"
            for w, o in out.items()
        )
        print(f"{goal:+.3f} {s} {int(need)} {fingers} | {cells}", flush=True)
    for (need, w), (it, t, ok, ov) in sorted(totals.items()):
        print(f"need={int(need)} way {w}: iterations {it}, time {t:.2f} s, passed {ok}, overlapping {ov}")


if __name__ == "__main__":
    main()
