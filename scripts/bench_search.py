"""Benchmark of the contact-sequence planner: median search time over the 60 goals of
seed 0 (target: under 0.2 s), and the per-call medians of its two primitives, the
form-closure LP (built once, updated per call) and one finger's Drake IK (SNOPT); also
the one-time cost of ranking the candidate initial grasps (kept in one GraspTables for every
goal, so the search times exclude it)."""

from __future__ import annotations

import argparse
import time

import numpy as np

from trajectotree.config import SearchConfig
from trajectotree.experiments.sweep import sample_goals
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.plant import build_scene
from trajectotree.search.grasp import FormClosureLp, grasp_matrix
from trajectotree.search.initial_grasp import GraspTables
from trajectotree.search.reach import Reachability
from trajectotree.search.tree import find_contact_plan


def lp_times(boundary: ConvexPolygon, mu: float, count: int, rng) -> np.ndarray:
    """Seconds per UpdateCoefficients + Solve of the 4-contact LP on random contacts."""
    lp = FormClosureLp(4, mu)
    out = []
    for _ in range(count):
        p, n = zip(*(boundary.point(s) for s in rng.uniform(0, boundary.perimeter, 4)))
        G = grasp_matrix(np.array(p), np.array(n))
        t0 = time.perf_counter()
        lp.solve(G)
        out.append(time.perf_counter() - t0)
    return np.array(out)


def ik_times(reach: Reachability, count: int, rng) -> np.ndarray:
    """Seconds per Drake IK solve (seeded by the closed form) on reachable contacts."""
    out = []
    while len(out) < count:
        finger, pose = int(rng.integers(4)), (0.0, 0.0, rng.uniform(-np.pi, np.pi))
        s = rng.uniform(0, reach.boundary.perimeter)
        guess = reach.closed_form(pose, finger, s)
        if guess.reachable:
            t0 = time.perf_counter()
            reach._drake_ik(finger, reach.tip_target(pose, s), guess.q)
            out.append(time.perf_counter() - t0)
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--goals", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--calls", type=int, default=500, help="LP and IK calls to time")
    args = parser.parse_args()
    scene, config = build_scene(), SearchConfig()
    rng = np.random.default_rng(args.seed)
    lp = lp_times(scene.config.shape, scene.config.mu, args.calls, rng)
    ik = ik_times(Reachability(scene), args.calls, rng)
    t0 = time.perf_counter()
    tables = GraspTables()
    table = tables.get(scene, config)  # cold: built once for these settings
    table_time = time.perf_counter() - t0
    find_contact_plan(scene, 1.0, config, tables)  # warm-up: imports, first solver loads
    plans, cpu = [], []
    for goal in sample_goals(args.goals, args.seed):
        t0 = time.process_time()
        plans.append(find_contact_plan(scene, goal, config, tables))
        cpu.append(time.process_time() - t0)
    times = np.array([p.stats.time_s for p in plans])
    print(f"form-closure LP (update + solve): median {1e6 * np.median(lp):.0f} us over {len(lp)} calls")
    print(f"finger IK (Drake, SNOPT, seeded): median {1e6 * np.median(ik):.0f} us over {len(ik)} calls")
    print(
        f"initial grasp candidates: {len(table.candidates)} ranked of {table.assignments} grid grasps "
        f"in {table_time:.3f} s (once for all goals)"
    )
    print(
        f"search over {len(plans)} goals (seed {args.seed}, N = {config.num_nodes}): "
        f"{sum(p.success for p in plans)} found; median {np.median(times):.3f} s, "
        f"mean {times.mean():.3f} s, max {times.max():.3f} s (target: median < 0.2 s); "
        f"CPU time median {np.median(cpu):.3f} s (this process; excludes waiting for a busy CPU); "
        f"median {np.median([p.stats.expanded for p in plans]):.0f} expansions, "
        f"{np.median([p.stats.lp_calls for p in plans]):.0f} LP and "
        f"{np.median([p.stats.ik_calls for p in plans]):.0f} IK calls per search, "
        f"at most {max(p.stats.initial_grasps_searched for p in plans)} initial grasps searched"
    )


if __name__ == "__main__":
    main()
