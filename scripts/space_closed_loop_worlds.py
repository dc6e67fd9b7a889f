"""Plans in space executed open and closed loop in worlds they did not assume (issue 37 item 2, docs/measurements.md
"Executing plans in space, closed loop"): `python scripts/space_closed_loop_worlds.py OUT.jsonl N [TRIALS_DIR]` runs
the first N plan folders of TRIALS_DIR (default /work/sweeps/space30/trials, a sweep's) nominal, at friction 0.4,
with the cube 1.5x heavier and under a 1 N push along +x for sim.push_duration from the middle of the middle
segment, each with grasp and grasp-closed-loop, one at a time; a row per run is appended to OUT.jsonl (runs already
there are skipped)."""

import json
import sys
import time
from pathlib import Path

from trajectotree.cli.space_simulate import read_space_plan
from trajectotree.config import config_from_dict
from trajectotree.execution.space_control import SpaceReference
from trajectotree.execution.space_run import simulate_space
from trajectotree.execution.world import Conditions, Push
from trajectotree.experiments.conditions import middle_of_middle_segment
from trajectotree.scene.spatial import build_space_scene

out = Path(sys.argv[1])
limit = int(sys.argv[2])
done = set()
if out.exists():
    done = {(r["trial"], r["world"], r["executor"]) for r in map(json.loads, out.read_text().splitlines())}
trials = sorted(Path(sys.argv[3] if len(sys.argv) > 3 else "/work/sweeps/space30/trials").iterdir())[:limit]
for trial in trials:
    if not (trial / "plan.npz").exists():
        continue
    data, arrays = read_space_plan(trial)
    if not data.get("success"):
        print(trial.name, "plan failed", flush=True)
        continue
    config = config_from_dict(data["config"])
    cube = data["object"]
    scene = build_space_scene(
        config.scene.hand, mu=config.scene.mu, gravity=config.scene.gravity, size=cube["size"], mass=cube["mass"]
    )
    ref = SpaceReference.from_arrays(arrays)
    t_push = middle_of_middle_segment(config, ref.duration)
    worlds = {
        "nominal": Conditions(),
        "friction-0.4": Conditions(mu=0.4),
        "mass-x1.5": Conditions(mass=1.5 * scene.object.mass),
        "push-1N": Conditions(push=Push(force=(1.0, 0.0), time_s=t_push, duration_s=config.sim.push_duration)),
    }
    for world, cond in worlds.items():
        for ex in ("grasp", "grasp-closed-loop"):
            if (trial.name, world, ex) in done:
                continue
            t0 = time.time()
            r = simulate_space(ref, config, scene, executor=ex, conditions=cond)
            j = r.to_json()
            row = {
                "trial": trial.name,
                "world": world,
                "executor": ex,
                "dropped": j["dropped"],
                "drop_time_s": j["drop_time_s"],
                "final_deg": j["final_orientation_error_deg"],
                "final_mm": 1e3 * j["final_position_error_m"],
                "within_15deg": j["within_15deg"],
                "duration_s": j["duration_s"],
                "push_s": t_push if world.startswith("push") else None,
                "wall_s": time.time() - t0,
                **(
                    {
                        "mu_est": j["closed_loop"]["mu_estimate"],
                        "mass_est": j["closed_loop"]["mass_estimate"],
                        "reflex_s": j["closed_loop"]["reflex_s"],
                    }
                    if "closed_loop" in j
                    else {}
                ),
            }
            print(json.dumps(row), flush=True)
            with out.open("a") as f:
                f.write(json.dumps(row) + "\n")
