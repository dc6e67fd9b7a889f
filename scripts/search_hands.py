"""The contact search on each built-in hand: how many of 12 seed-0 goals it finds a contact
sequence for, and the median search time, in one run (docs/measurements.md, "Hands").

    python scripts/search_hands.py [--goals 12] [--seed 0]

Drake's planar gripper holds Drake's planar brick (0.1 x 0.1 m, 28 g) with goals in [-pi/2, pi/2];
the four- and five-finger hands the default box with goals in [-pi, pi]. The search only: CITO,
execution and the figures take four fingers yet.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

from trajectotree.config import SceneConfig, SearchConfig
from trajectotree.experiments.sweep import sample_goals
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables
from trajectotree.search.tree import find_contact_plan

HANDS = (
    ("planar_hand", SceneConfig(), math.pi),
    ("planar_hand5", SceneConfig(hand="planar_hand5"), math.pi),
    (
        "drake_planar_gripper",
        SceneConfig(hand="drake_planar_gripper", box_width=0.1, box_height=0.1, box_mass=0.028),
        math.pi / 2,
    ),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goals", type=int, default=12)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for name, scene_config, max_abs in HANDS:
        scene, tables, search = build_scene(scene_config), GraspTables(), SearchConfig()
        found, times, failed = 0, [], []
        for goal in sample_goals(args.goals, args.seed, max_abs):
            t0 = time.perf_counter()
            plan = find_contact_plan(scene, float(goal), search, tables)
            times.append(time.perf_counter() - t0)
            found += plan.success
            if not plan.success:
                failed.append(round(float(goal), 3))
        print(
            f"{name}: {scene.num_fingers} fingers, goals in [-{max_abs:.4g}, {max_abs:.4g}] rad: "
            f"found {found}/{args.goals}, median search {statistics.median(times):.3f} s "
            f"(first, with the grasp table: {times[0]:.3f} s); no sequence for {failed}"
        )


if __name__ == "__main__":
    main()
