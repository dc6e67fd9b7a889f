"""Per-iteration cost of the CITO program by size.

For each number of segments S (--segments, default 1 2 9: 13, 25 and 109 knots) and goal
(--goals; S = 9 uses the first goal only, one solve takes seconds), the search's contact
plan is found once, then TrajectoTree's joint program is built and solved; printed are
medians over goals and rounds of ms per IPOPT iteration: the solve's CPU time (the least
disturbed by other processes on a shared machine), function evaluations and IPOPT's own
time (IPOPT's totals, wall clock), of it the linear solver's factorizations and back-solves
(IPOPT's timing statistics, CPU), with the iterations and the build time (program and guess, ms).

--compare DIR measures a second copy of the package the same way in the same run (e.g. the
tree before a change: `git archive REV trajectotree | tar -x -C DIR`), alternating with this
one round by round, each measurement in its own process; the machine's load average is
printed before and after, since this 2-core machine is shared.

    python scripts/profile_segment.py --compare /tmp/before --rounds 3
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent  # this checkout (its trajectotree package)
KEYS = (
    "iterations",
    "cpu_ms_per_it",
    "fev_ms_per_it",
    "own_ms_per_it",
    "factor_ms_per_it",
    "solve_ms_per_it",
    "build_ms",
)


def measure(segments: int, goals: list[float]) -> list[dict]:
    """One build and solve per goal of the joint program with `segments` segments."""
    from trajectotree.cito.guess import plan_guess
    from trajectotree.cito.knot import BodyParams
    from trajectotree.cito.program import build_program
    from trajectotree.cito.solve import solve
    from trajectotree.cito.transition import transition_spec
    from trajectotree.config import Config, mu_plan
    from trajectotree.scene.plant import build_scene
    from trajectotree.search.tree import find_contact_plan

    base = Config()
    config = dataclasses.replace(base, search=dataclasses.replace(base.search, num_nodes=segments + 1))
    scene = build_scene(config.scene)
    body = BodyParams(scene, config.cito.sdf_sharpness, mu=mu_plan(config.scene, config.search))
    rows = []
    for goal in goals:
        contact_plan = find_contact_plan(scene, goal, config.search)
        if not contact_plan.success:
            continue
        spec = transition_spec(contact_plan, radius=scene.tip_radius, config=config.cito)
        t0 = time.perf_counter()
        program = build_program(config.cito, spec, body)
        guess = plan_guess(program.rows, spec, contact_plan)
        build_ms = 1e3 * (time.perf_counter() - t0)
        cpu0 = time.process_time()
        # the linear solver's times need IPOPT's timing statistics, off by default since issue 35
        timed = "timing_statistics" in inspect.signature(solve).parameters
        outcome = solve(program, guess, config.cito, **({"timing_statistics": True} if timed else {}))
        cpu_ms = 1e3 * (time.process_time() - cpu0)
        t, it = outcome.timing, max(outcome.iterations, 1)
        per_it = {
            name: 1e3 * t.get(key, np.nan) / it
            for name, key in (
                ("fev_ms_per_it", "nlp_function_evaluations_s"),
                ("own_ms_per_it", "ipopt_without_function_evaluations_s"),
                ("factor_ms_per_it", "linear_system_factorization_s"),
                ("solve_ms_per_it", "linear_system_back_solve_s"),
            )
        }
        rows.append(
            {
                "segments": segments,
                "knots": spec.num_knots,
                "goal": goal,
                "success": outcome.success,
                "iterations": outcome.iterations,
                "cost": outcome.cost,
                "build_ms": build_ms,
                "cpu_ms_per_it": cpu_ms / it,
                **per_it,
            }
        )
    return rows


def run_worker(package_root: Path, segments: int, goals: list[float]) -> list[dict]:
    """measure() in a fresh process importing trajectotree from package_root."""
    env = {**os.environ, "PYTHONPATH": str(package_root), "OMP_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, __file__, "--worker", str(segments), "--goals", *map(str, goals)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--segments", type=int, nargs="+", default=[1, 2, 9])
    parser.add_argument("--goals", type=float, nargs="+", default=[0.3, -1.2, 2.5])
    parser.add_argument("--rounds", type=int, default=3, help="repetitions of every measurement")
    parser.add_argument("--compare", type=Path, help="folder holding another trajectotree package")
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        print(json.dumps(measure(args.worker, args.goals)))
        return
    trees = {"this": HERE} | ({"compare": args.compare.resolve()} if args.compare else {})
    results = {name: [] for name in trees}
    print(f"load average before: {os.getloadavg()[0]:.2f} (cores: {os.cpu_count()})", flush=True)
    for r in range(args.rounds):
        for S in args.segments:
            goals = args.goals[:1] if S >= 9 else args.goals
            for name in list(trees) if r % 2 else list(trees)[::-1]:  # alternate who goes first
                results[name] += run_worker(trees[name], S, goals)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print("medians over goals and rounds; ms per IPOPT iteration unless noted")
    print(f"{'tree':8s} {'S':>2s} {'knots':>5s} {'n':>3s} " + " ".join(f"{k:>16s}" for k in KEYS))
    for S in args.segments:
        for name, rows in results.items():
            sel = [row for row in rows if row["segments"] == S]
            if sel:
                med = [np.median([row[k] for row in sel]) for k in KEYS]
                print(f"{name:8s} {S:2d} {sel[0]['knots']:5d} {len(sel):3d} " + " ".join(f"{m:16.2f}" for m in med))
    if args.compare:  # the same goals in both trees: their iterations and costs should agree
        for S in args.segments:
            pairs = {
                (row["goal"], row["iterations"], row["cost"])
                for name in trees
                for row in results[name]
                if row["segments"] == S
            }
            agree = len(pairs) == len({p[0] for p in pairs})
            print(
                f"S={S}: (goal, iterations, cost) {'agree in both trees' if agree else 'DIFFER: ' + str(sorted(pairs))}"
            )


if __name__ == "__main__":
    main()
