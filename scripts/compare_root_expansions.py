"""The planar search at two values of search.root_expansions, goal by goal in one process.

For each goal set, each goal searched at --old and then at --new expansions per initial grasp (the
initial-grasp tables built once per scene for both), and compared: success, the contact sequence
node by node (every field of every node), expansions, initial grasps searched and CPU seconds.
Prints one line per goal whose answer differs and a summary per set (issue 35: the +3.021 goal's
fine grid spent 2 x 2000 expansions on two roots that found nothing).

    python scripts/compare_root_expansions.py [--old 2000] [--new 1000] [--sets box76 hands shapes]

Sets: box76, the 60 paper goals (seed 0) and the 16 held-out goals of scripts/bench_planning.py
--goal-set both on the default box; hands, 60 seed-0 goals on planar_hand5 and Drake's planar gripper
(scripts/search_hands.py's scenes and goal ranges); shapes, 60 seed-0 goals on each polygon of
scripts/polygon_gallery.py.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the sibling scripts' scenes and goals

from bench_planning import goal_list  # noqa: E402
from polygon_gallery import SHAPES, shape_config  # noqa: E402
from search_hands import HANDS  # noqa: E402

from trajectotree.config import SceneConfig, SearchConfig  # noqa: E402
from trajectotree.experiments.sweep import sample_goals  # noqa: E402
from trajectotree.scene.plant import build_scene  # noqa: E402
from trajectotree.search.initial_grasp import GraspTables  # noqa: E402
from trajectotree.search.tree import find_contact_plan  # noqa: E402


def goal_sets(names: list[str]) -> list[tuple[str, SceneConfig, np.ndarray]]:
    sets = []
    if "box76" in names:
        both = argparse.Namespace(goal_list=None, goals=60, seed=0, goal_set="both")
        sets.append(("box76", SceneConfig(), np.array(goal_list(both))))
    if "hands" in names:
        sets += [(name, scene, sample_goals(60, 0, max_abs)) for name, scene, max_abs in HANDS[1:]]
    if "shapes" in names:
        sets += [(name, shape_config(vertices).scene, sample_goals(60, 0)) for name, vertices in SHAPES.items()]
    return sets


def search(scene, goal: float, config: SearchConfig, tables: GraspTables) -> dict:
    c0 = time.process_time()
    plan = find_contact_plan(scene, goal, config, tables)
    return {
        "success": plan.success,
        "nodes": [n.to_json() for n in plan.nodes],
        "reason": plan.reason,
        "expanded": plan.stats.expanded,
        "roots": plan.stats.initial_grasps_searched,
        "cpu": time.process_time() - c0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--old", type=int, default=2000, help="search.root_expansions of the reference")
    parser.add_argument("--new", type=int, default=1000, help="search.root_expansions compared with it")
    parser.add_argument("--sets", nargs="+", default=["box76", "hands", "shapes"], choices=["box76", "hands", "shapes"])
    parser.add_argument("--json", metavar="FILE", help="also write every goal's two answers here (JSON lines)")
    args = parser.parse_args()
    configs = {k: dataclasses.replace(SearchConfig(), root_expansions=getattr(args, k)) for k in ("old", "new")}
    out = open(args.json, "w") if args.json else None
    for name, scene_config, goals in goal_sets(args.sets):
        scene, tables = build_scene(scene_config), GraspTables()
        rows = []
        for goal in map(float, goals):
            row = {"set": name, "goal": goal, **{k: search(scene, goal, c, tables) for k, c in configs.items()}}
            rows.append(row)
            if out:
                out.write(json.dumps(row) + "\n")
                out.flush()
            old, new = row["old"], row["new"]
            if old["nodes"] != new["nodes"] or old["success"] != new["success"]:
                print(
                    f"  {name} goal {goal:+.4f}: {'ok' if old['success'] else 'none'} -> "
                    f"{'ok' if new['success'] else 'none'}, {'same' if old['nodes'] == new['nodes'] else 'other'} "
                    f"sequence ({len(old['nodes'])} -> {len(new['nodes'])} nodes), expanded {old['expanded']} -> "
                    f"{new['expanded']}, roots {old['roots']} -> {new['roots']}, cpu {old['cpu']:.2f} -> "
                    f"{new['cpu']:.2f} s; {old['reason'] or new['reason']}",
                    flush=True,
                )
        summary(name, rows)


def summary(name: str, rows: list[dict]) -> None:
    same = sum(r["old"]["nodes"] == r["new"]["nodes"] and r["old"]["success"] == r["new"]["success"] for r in rows)
    differ = sum(r["old"]["expanded"] != r["new"]["expanded"] for r in rows)
    print(
        f"{name}: {len(rows)} goals; identical answers {same}/{len(rows)}; expansions differ on {differ}; "
        + "; ".join(side(k, rows) for k in ("old", "new")),
        flush=True,
    )


def side(key: str, rows: list[dict]) -> str:
    """One budget's totals over a set: plans found, expansions, CPU seconds."""
    found = sum(r[key]["success"] for r in rows)
    expanded = sum(r[key]["expanded"] for r in rows)
    cpu = np.array([r[key]["cpu"] for r in rows])
    return (
        f"{key}: found {found}, expanded {expanded}, cpu s median {np.median(cpu):.3f} "
        f"max {cpu.max():.2f} sum {cpu.sum():.1f}"
    )


if __name__ == "__main__":
    main()
