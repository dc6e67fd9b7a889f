"""How close two fingers come in a sweep's plans: the exact signed distance between any two fingers'
collision shapes (link boxes and fingertip spheres, trajectotree.scene.finger_clearance) at every
knot of every plan.npz, and on the straight joint-space path between knots (--between samples per
interval), in the simulated run where the trial has one (its sim.npz's, else its first exec/*/sim.npz's
logged joint angles, every sample: 0 or less means two fingers touched), and, given a second sweep (--against), how many
plans' arrays differ.

    python scripts/finger_clearance.py SWEEP [--between 10] [--against OTHER_SWEEP] [--json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from trajectotree.io import load_plan
from trajectotree.results import TRAJECTORY_ARRAYS
from trajectotree.scene.finger_clearance import closest_fingers, interpolate_joints
from trajectotree.scene.plant import build_scene


def plan_dirs(sweep: Path) -> dict[str, Path]:
    """{trial name: its folder} of the trials with a plan.npz."""
    return {p.parent.name: p.parent for p in sorted((sweep / "trials").glob("*/plan.npz"))}


def measure(sweep: Path, between: int) -> dict:
    scenes, rows = {}, {}
    for name, folder in plan_dirs(sweep).items():
        result = load_plan(folder)
        if result.trajectory is None:
            continue
        key = repr(result.config.scene)
        scene = scenes.setdefault(key, build_scene(result.config.scene))
        q = result.trajectory.q
        knots = closest_fingers(scene.fingers, q, scene.tip_radius)
        dense = closest_fingers(scene.fingers, interpolate_joints(q, between), scene.tip_radius)
        executed, runs = None, [folder / "sim.npz", *sorted(folder.glob("exec/*/sim.npz"))]
        run = next((path for path in runs if path.exists()), None)
        if run is not None:
            with np.load(run) as sim:
                executed = closest_fingers(scene.fingers, sim["q"], scene.tip_radius).distance
        rows[name] = {
            "executed_m": executed,
            "knots_m": knots.distance,
            "knot": knots.knot,
            "fingers": list(knots.fingers),
            "between_m": dense.distance,
            "between_fingers": list(dense.fingers),
            "passed": bool(result.physics_check is not None and result.physics_check.passed),
        }
    return rows


def changed(a: Path, b: Path) -> list[str]:
    """Trials whose plan.npz arrays differ (or exist in one sweep only)."""
    da, db = plan_dirs(a), plan_dirs(b)
    out = []
    for name in sorted(set(da) | set(db)):
        if name not in da or name not in db:
            out.append(name)
            continue
        with np.load(da[name] / "plan.npz") as x, np.load(db[name] / "plan.npz") as y:
            if any(n not in x or n not in y or not np.array_equal(x[n], y[n]) for n in TRAJECTORY_ARRAYS):
                out.append(name)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweep", type=Path)
    parser.add_argument("--between", type=int, default=10, help="samples per knot interval (default 10)")
    parser.add_argument("--against", type=Path, help="another sweep: count the plans whose arrays differ")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = measure(args.sweep, args.between)
    knots = np.array([r["knots_m"] for r in rows.values()])
    dense = np.array([r["between_m"] for r in rows.values()])
    worst = min(rows, key=lambda n: rows[n]["knots_m"])
    summary = {
        "plans": len(rows),
        "passed": sum(r["passed"] for r in rows.values()),
        "closest_at_knots_m": float(knots.min()),
        "closest_at_knots_trial": worst,
        "closest_at_knots_fingers": rows[worst]["fingers"],
        "closest_between_knots_m": float(dense.min()),
        "plans_within_5mm_at_knots": int(np.sum(knots < 0.005)),
        "plans_overlapping_at_knots": int(np.sum(knots < 0.0)),
        "plans_overlapping_between_knots": int(np.sum(dense < 0.0)),
    }
    executed = [r["executed_m"] for r in rows.values() if r["executed_m"] is not None]
    if executed:
        summary |= {
            "runs_simulated": len(executed),
            "closest_executed_m": float(min(executed)),
            "runs_with_fingers_touching": int(np.sum(np.array(executed) <= 0.0)),
        }
    if args.against is not None:
        diff = changed(args.sweep, args.against)
        summary |= {"plans_changed": len(diff), "changed_trials": diff}
    if args.json:
        print(json.dumps({"summary": summary, "plans": rows}, indent=1))
    else:
        for name, r in rows.items():
            print(
                f"{name}: knots {1e3 * r['knots_m']:7.2f} mm (fingers {r['fingers']}, knot {r['knot']}), "
                f"between {1e3 * r['between_m']:7.2f} mm, check {'passed' if r['passed'] else 'FAILED'}"
                + ("" if r["executed_m"] is None else f", executed {1e3 * r['executed_m']:7.2f} mm")
            )
        print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
