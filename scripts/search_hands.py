"""The contact search on each built-in hand: how many of 12 seed-0 goals it finds a contact
sequence for, and the median search time, in one run (docs/measurements.md, "Hands"); with
--plan, the whole TrajectoTree plan (search and CITO, segments serially) and its physics check.

    python scripts/search_hands.py [--goals 12] [--seed 0] [--plan] [--hands NAME ...]

Drake's planar gripper holds Drake's planar brick (its YAML's object: 0.1 x 0.1 m, 28 g, friction 1.0)
with goals in [-pi/2, pi/2]; the four- and five-finger hands the default box with goals in [-pi, pi].
Nothing here is simulated.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

from trajectotree.config import Config, SceneConfig, SearchConfig
from trajectotree.experiments.sweep import sample_goals
from trajectotree.planning.planners import plan as plan_goal
from trajectotree.scene.hand import with_hand_object
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables
from trajectotree.search.tree import find_contact_plan

HANDS = (
    ("planar_hand", SceneConfig(), math.pi),
    ("planar_hand5", SceneConfig(hand="planar_hand5"), math.pi),
    ("drake_planar_gripper", with_hand_object(SceneConfig(hand="drake_planar_gripper")), math.pi / 2),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goals", type=int, default=12)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plan", action="store_true", help="plan each goal (search and CITO), not only search")
    parser.add_argument("--hands", nargs="+", default=[name for name, _, _ in HANDS])
    args = parser.parse_args()
    for name, scene_config, max_abs in HANDS:
        if name not in args.hands:
            continue
        scene, tables, search = build_scene(scene_config), GraspTables(), SearchConfig()
        found, passed, times, failed = 0, 0, [], []
        for goal in sample_goals(args.goals, args.seed, max_abs):
            t0 = time.perf_counter()
            if args.plan:
                result = plan_goal(
                    goal=float(goal),
                    config=Config(scene=scene_config),
                    scene=scene,
                    segment_workers=1,
                    grasp_tables=tables,
                )
                ok = result.success and result.physics_check is not None and result.physics_check.passed
                found += result.success
                passed += ok
            else:
                ok = find_contact_plan(scene, float(goal), search, tables).success
                found += ok
            times.append(time.perf_counter() - t0)
            if not ok:
                failed.append(round(float(goal), 3))
        what = f"planned {found}/{args.goals}, physics check passed {passed}" if args.plan else f"found {found}"
        print(
            f"{name}: {scene.num_fingers} fingers, goals in [-{max_abs:.4g}, {max_abs:.4g}] rad: {what}/{args.goals}, "
            f"median {'plan' if args.plan else 'search'} {statistics.median(times):.3f} s "
            f"(first: {times[0]:.3f} s); failed {failed}",
            flush=True,
        )


if __name__ == "__main__":
    main()
