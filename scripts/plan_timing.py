"""One process of scripts/bench_planning.py's phase timing: plans the given goals with plan() of
whichever trajectotree package PYTHONPATH names (this checkout or an older one, --compare) and
writes one JSON row per plan: plan()'s wall-clock time split into search, first round, retries,
pool and other, and the plan's outcome. It uses only what every version of the package has:
plan(), build_scene, GraspTables and keyframes.run_pieces, which it wraps to time each round, and
keyframes.run_chains where the package has it (issue 35: each segment's retries in its own task).

    PYTHONPATH=TREE python scripts/plan_timing.py --goals 0.86,-1.45 --methods trajectotree --out rows.json

Phases of one keyframes plan (s): search (the contact search's own time); each call of run_pieces
or run_chains is a round (the first the first round, later ones retries); of a round, the part the
busiest worker process spent in its pieces (build and solve, summed per pid) counts to its round
(of the first round of chains, the busiest process's time in the segments' first attempts counts to
the first round and the rest of its busy time to retries) and the rest of the round's wall-clock time
(starting and stopping processes, sending tasks and results) to pool;
other is plan()'s wall-clock time outside the search and the rounds (checks, the guess, the stitch
and the physics check). start_up (per process): importing the planner and building the scene.
"""

from __future__ import annotations

import time

T_START = time.perf_counter()  # before the package's imports, which start-up counts

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import warnings  # noqa: E402

from trajectotree.planning import keyframes  # noqa: E402
from trajectotree.planning.planners import plan  # noqa: E402
from trajectotree.scene.plant import build_scene  # noqa: E402
from trajectotree.search.initial_grasp import GraspTables  # noqa: E402

IMPORTED = time.perf_counter()


def busiest(results) -> float:
    """s, the most any one process spent building and solving `results`."""
    busy = {}
    for r in results:
        busy[r.pid] = busy.get(r.pid, 0.0) + r.build_time_s + r.solve_time_s
    return max(busy.values())


def timed_rounds(rounds: list[dict], original):
    """keyframes.run_pieces or run_chains (`original`), recording each call's wall-clock time, its busiest
    worker's time and, of chains, the busiest worker's time in their first attempts in `rounds`."""

    def run(tasks, *args, **kwargs):
        t0 = time.perf_counter()
        results = original(tasks, *args, **kwargs)
        if not tasks:  # a retry round with nothing to retry
            return results
        chains = [r if isinstance(r, tuple) else (r,) for r in results]
        busy = busiest([a for chain in chains for a in chain])
        rounds.append(
            {
                "wall_s": time.perf_counter() - t0,
                "busy_s": busy,
                "first_busy_s": busiest([chain[0] for chain in chains]),
                "kinds": sorted({t.kind for t in tasks}),
            }
        )
        return results

    return run


def plan_row(goal: float, method: str, scene, tables, rounds: list[dict]) -> dict:
    """plan() of one goal, timed from outside, with its phases."""
    rounds.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        r = plan(goal=goal, method=method, scene=scene, grasp_tables=tables)
        wall = time.perf_counter() - t0
    first, later = rounds[:1], rounds[1:]
    in_rounds = sum(x["wall_s"] for x in rounds)
    segments = r.segments or ()
    return {
        "goal": goal,
        "method": method,
        "success": bool(r.success),
        "wall_s": wall,
        "search_s": r.search_time_s,
        "first_round_s": sum(x["first_busy_s"] for x in first),
        "retries_s": sum(x["busy_s"] - x["first_busy_s"] for x in first) + sum(x["busy_s"] for x in later),
        "pool_s": sum(x["wall_s"] - x["busy_s"] for x in rounds),
        "other_s": wall - r.search_time_s - in_rounds,
        "retry_rounds": len(later),
        "retries": sum(s["retries"] for s in segments),  # attempts after each segment's first (a joint one per segment)
        "retry_kinds": sorted({k for x in later for k in x["kinds"]}),
        "iterations": r.iterations,
        "segment_iterations": [s["iterations"] for s in segments],
        "physics_passed": r.physics_check is not None and r.physics_check.passed,
        "final_error_deg": math.nan if r.trajectory is None else math.degrees(abs(r.trajectory.x[-1, 2] - r.goal)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goals", required=True, help="comma-separated goal rotations, rad")
    parser.add_argument("--methods", default="trajectotree")
    parser.add_argument("--out", required=True, help="JSON file of the rows")
    args = parser.parse_args()
    scene, tables = build_scene(), GraspTables()
    start_up = time.perf_counter() - T_START
    rounds: list[dict] = []
    keyframes.run_pieces = timed_rounds(rounds, keyframes.run_pieces)
    if hasattr(keyframes, "run_chains"):
        keyframes.run_chains = timed_rounds(rounds, keyframes.run_chains)
    rows = [
        plan_row(float(g), m, scene, tables, rounds) for g in args.goals.split(",") for m in args.methods.split(",")
    ]
    with open(args.out, "w") as f:
        json.dump({"start_up_s": start_up, "import_s": IMPORTED - T_START, "rows": rows}, f)


if __name__ == "__main__":
    main()
