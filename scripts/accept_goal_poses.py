"""Random goal poses on the default box, planned, checked and executed: the acceptance run of goal poses.

Draws --goals goal poses with --seed: the translation uniform in the disc of the workspace that
`trajectotree scene` reports as graspable at every orientation (its radius, about the start), the
orientation uniform in [-MAX, MAX] (--max-theta, default 2 pi). Each goal is planned with the default
settings (TrajectoTree, keyframes; the segment count follows from the distance), its physics check
read, and the plan executed with the default grasp controller. A goal counts as reached when the plan
passed the physics check, the run did not drop the object, and its last simulated pose is within
--position-tol (3 mm) and --angle-tol (3 deg) of the goal itself (the orientation unwrapped: a turn
too few is a miss). Prints one row per goal and the counts; with --out DIR each goal's plan and run
are kept in DIR/NNNN/ (plan.json, plan.npz, sim.json, sim.npz) and a rerun with the same arguments
skips the goals already there, so a killed run resumes. --plan-only plans the goals and stops.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from trajectotree.config import Config, ConfigError, GoalPose
from trajectotree.execution.run import run_simulation
from trajectotree.io import load_plan, load_sim, save_plan, save_sim
from trajectotree.planning.planners import plan
from trajectotree.scene.plant import build_scene
from trajectotree.search.workspace import workspace


def sample_goal_poses(count: int, seed: int, radius: float, max_theta: float, start) -> np.ndarray:
    """(count, 3): positions uniform in the disc of `radius` about start's, theta uniform in [-max, max]."""
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.uniform(0.0, 1.0, count))
    phi = rng.uniform(-math.pi, math.pi, count)
    theta = rng.uniform(-max_theta, max_theta, count)
    return np.column_stack([start[0] + r * np.cos(phi), start[1] + r * np.sin(phi), theta])


def run_goal(goal, config: Config, scene, folder: Path | None, plan_only: bool, workers: int) -> dict:
    """Plans and executes one goal pose (reusing what `folder` already holds); its row."""
    row = {"goal": [float(v) for v in goal]}
    pose = GoalPose(theta=float(goal[2]), position=(float(goal[0]), float(goal[1])))
    if folder is not None and (folder / "plan.json").exists():
        result = load_plan(folder)
    else:
        try:
            result = plan(scene=scene, goal=pose, config=config, segment_workers=workers)
        except ConfigError as e:  # a goal whose path leaves the workspace: refused before planning
            return row | {"planned": False, "passed": False, "reason": str(e)}
        if folder is not None:
            save_plan(result, folder)
    row |= {"planned": result.success, "nodes": len(result.contact_plan.nodes) if result.contact_plan else 0}
    row |= {"passed": bool(result.physics_check is not None and result.physics_check.passed)}
    row |= {"search_s": result.search_time_s, "total_s": result.total_time_s, "status": result.status[:120]}
    if plan_only or result.trajectory is None:
        return row
    if folder is not None and (folder / "sim.json").exists():
        sim = load_sim(folder)
    else:
        sim = run_simulation(plan=result)
        if folder is not None:
            save_sim(sim, folder)
    final = np.asarray(sim.x[-1], dtype=float)
    row |= {"dropped": bool(sim.dropped), "drop_time_s": sim.drop_time_s}
    row |= {"position_error_m": float(np.hypot(*(final[:2] - goal[:2]))), "angle_error_rad": float(final[2] - goal[2])}
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-theta", type=float, default=2 * math.pi, metavar="RAD")
    parser.add_argument("--position-tol", type=float, default=0.003, metavar="M")
    parser.add_argument("--angle-tol", type=float, default=3.0, metavar="DEG")
    parser.add_argument("--segment-workers", type=int, default=1, help="keyframes segment processes per plan")
    parser.add_argument("--out", metavar="DIR", help="keep each goal's plan and run here (resumable)")
    parser.add_argument("--plan-only", action="store_true")
    parser.add_argument("--only", type=int, nargs="+", metavar="I", help="run only these goal indices")
    parser.add_argument("--json", metavar="FILE", help="write the rows")
    args = parser.parse_args()
    config = Config()
    scene = build_scene(config.scene)
    region = workspace(scene, config.search).to_json()["every_orientation"]
    radius = region["radius_m"]
    goals = sample_goal_poses(args.goals, args.seed, radius, args.max_theta, config.scene.initial_pose)
    print(f"workspace at every orientation: radius {radius:.4f} m ({region['points']} grid points); {args.goals} goals")
    out = Path(args.out) if args.out else None
    rows = []
    for i, goal in enumerate(goals):
        if args.only and i not in args.only:
            continue
        t0 = time.perf_counter()
        folder = None if out is None else out / f"{i:04d}"
        row = {"index": i} | run_goal(goal, config, scene, folder, args.plan_only, args.segment_workers)
        row["wall_s"] = time.perf_counter() - t0
        tol_ok = row.get("position_error_m", math.inf) <= args.position_tol and abs(
            row.get("angle_error_rad", math.inf)
        ) <= math.radians(args.angle_tol)
        row["reached"] = bool(row["passed"] and row.get("dropped") is False and tol_ok)
        rows.append(row)
        executed = (
            ""
            if "dropped" not in row
            else (
                f", dropped {row['dropped']}, final error {row['position_error_m'] * 1e3:.2f} mm "
                f"{math.degrees(row['angle_error_rad']):+.2f} deg"
            )
        )
        print(
            f"{i:2d} goal ({goal[0] * 1e3:+6.1f} mm, {goal[1] * 1e3:+6.1f} mm, {goal[2]:+7.3f} rad): "
            f"{row.get('nodes', 0):3d} nodes, planned {row['planned']}, physics check {row['passed']}"
            f"{executed}, reached {row['reached']} ({row['wall_s']:.0f} s)",
            flush=True,
        )
    n = len(rows)
    counts = {
        "planned and passed the physics check": sum(r["passed"] for r in rows),
        "executed without a drop": sum(r.get("dropped") is False for r in rows),
        f"within {args.position_tol * 1e3:g} mm and {args.angle_tol:g} deg of the goal": sum(
            r["reached"] for r in rows
        ),
    }
    for what, k in counts.items():
        print(f"{what}: {k}/{n}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
