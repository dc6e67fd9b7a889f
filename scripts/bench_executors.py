"""The executors on the same saved plans, this tree beside another (`--compare TREE`): drops, bit-identical runs
and replanning latency per (executor, condition), both trees in the same run.

    python scripts/bench_executors.py SWEEP --out DIR --compare TREE \\
        [--stages grasp:nominal grasp-closed-loop:friction-0.4 grasp-replan:friction-0.4 ...] [--goals N]
        [--trials I [I ...]]

SWEEP is a sweep folder whose trials hold plans (`trajectotree sweep --methods trajectotree --out SWEEP`). Each
tree gets its own copy of the plans under DIR/this and DIR/other (a tree from before the controller's settings were
grouped reads a plan.json rewritten for it: the groups flattened, controller.replan back to sim.replan, the keys its
Config does not know dropped; the arrays untouched). Each stage runs in both trees at once, one process each
(PYTHONPATH), the trials one after another, through the tree's own `experiments.executions.execute` as the sweep's
executions do; a stage whose runs exist is not run again (the benchmark resumes). Replanned runs depend on the
machine's speed (the world waits for no planner), so both trees run side by side under the same load.

Printed per stage and tree: runs, drops (goal indices), within 3 deg; how many runs are bit-identical between
the trees (sim.npz arrays); for replanning, the replans by outcome and their latency (measured state in, first
segment ready) median / p95 / max, over every replan and over those that gave a plan."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # this tree
DEFAULT_STAGES = (
    "grasp:nominal",
    "grasp-closed-loop:friction-0.4",
    "grasp-replan:friction-0.4",
    "grasp-closed-loop:push-6N",
    "grasp-closed-loop:friction-0.3",
    "grasp-replan:friction-0.3",
    "grasp-replan:push-6N",
)

# Run in the tree's own Python (PYTHONPATH=tree): rewrite a plan.json for that tree's Config.
CONVERT = r"""
import dataclasses, json, sys, typing
from trajectotree import config as c
Config = c.Config
src, dst = sys.argv[1], sys.argv[2]
data = json.load(open(src))
cfg = data["config"]
grouped = hasattr(c, "controller") and hasattr(c.controller, "FLAT_KEYS")
if not grouped:
    flat = {}
    for key, value in cfg.get("controller", {}).items():
        if key == "replan":
            cfg.setdefault("sim", {})["replan"] = value
        elif isinstance(value, dict):
            prefix = {"push_reflex": "reflex_", "landing_reflex": "land_"}.get(key, "")
            for name, v in value.items():
                flat[name if name == "disturbance_feedforward" else prefix + name] = v
        else:
            flat[key] = value
    cfg["controller"] = flat
def keep(section, cls):
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    return {k: keep(v, hints[k]) if isinstance(v, dict) and dataclasses.is_dataclass(hints[k]) else v
            for k, v in section.items() if k in names}
data["config"] = keep(cfg, Config)
json.dump(data, open(dst, "w"), indent=2)
"""

# Run in the tree's own Python: execute the stage's pending trials, one after another.
EXECUTE = r"""
import dataclasses, sys
from pathlib import Path
from trajectotree.experiments import executions as ex
spec_module = ex if hasattr(ex, "ConditionSpec") else __import__("trajectotree.experiments.conditions", fromlist=["x"])
trials, executor, condition = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
fields = {f.name for f in dataclasses.fields(ex.ExecutionTask)}
for trial in sorted(p for p in trials.iterdir() if (p / "plan.npz").exists()):
    if "executor" in fields:
        from trajectotree.config.executor import parse_executor
        task = ex.ExecutionTask(str(trial), parse_executor(executor), condition, spec_module.ConditionSpec())
    else:  # before the executor was one typed value
        task = ex.ExecutionTask(str(trial), "grasp", condition, spec_module.ConditionSpec(),
                                closed_loop=executor != "grasp", replan=executor == "grasp-replan")
    if not (task.folder / "sim.json").exists():
        ex.execute(task)
        print(trial.name, flush=True)
"""


def copy_plans(sweep: Path, dst: Path, tree: Path, goals: int | None, indices: list[int] | None = None) -> Path:
    """dst/trials/<trial>/plan.{json,npz} for `tree` (plan.json rewritten by CONVERT in that tree), of the first
    `goals` trials (None: all) or those numbered `indices` (the trial folders' leading number); dst/trials."""
    trials = sorted(p for p in (sweep / "trials").iterdir() if (p / "plan.npz").exists())[:goals]
    if indices is not None:
        trials = [p for p in trials if int(p.name[:4]) in indices]
    for trial in trials:
        out = dst / "trials" / trial.name
        if (out / "plan.json").exists():
            continue
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(trial / "plan.npz", out / "plan.npz")
        run_in(tree, CONVERT, str(trial / "plan.json"), str(out / "plan.json"))
    return dst / "trials"


# `python -c` puts the working directory first on sys.path, ahead of PYTHONPATH: run from a checkout, both
# "trees" imported that checkout's package. -P leaves it out, so each tree runs its own.
def run_in(tree: Path, code: str, *args: str) -> None:
    subprocess.run([sys.executable, "-P", "-c", code, *args], env=dict(os.environ, PYTHONPATH=str(tree)), check=True)


def run_stage(trees: dict[str, tuple[Path, Path]], executor: str, condition: str) -> None:
    """The stage in every tree at once (a process each), until each has run all its trials."""
    procs = [
        subprocess.Popen(
            [sys.executable, "-P", "-c", EXECUTE, str(trials), executor, condition],
            env=dict(os.environ, PYTHONPATH=str(tree)),
            stdout=subprocess.DEVNULL,
        )
        for tree, trials in trees.values()
    ]
    for p in procs:
        if p.wait() != 0:
            raise SystemExit(f"a tree's executions failed (exit {p.returncode}): {executor} {condition}")


def execution_folder(trial: Path, executor: str, condition: str) -> Path:
    """The execution's folder in either layout (exec/<executor>_<condition>; the grasp executors were named so)."""
    return trial / "exec" / f"{executor}_{condition}"


def summary(trials: Path, executor: str, condition: str) -> dict:
    runs, drops, within, latency, planned, outcomes = 0, [], 0, [], [], {}
    for trial in sorted(trials.iterdir()):
        path = execution_folder(trial, executor, condition) / "sim.json"
        if not path.exists():
            continue
        run = json.loads(path.read_text())
        runs += 1
        if run["dropped"]:
            drops.append(int(trial.name[:4]))
        within += (not run["dropped"]) and abs(run["final_error"][2]) <= np.radians(3.0)
        for event in run.get("replans") or []:
            latency.append(event["latency_s"])
            outcomes[event["outcome"]] = outcomes.get(event["outcome"], 0) + 1
            if event["outcome"] in ("planned", "partial"):
                planned.append(event["latency_s"])
    return {
        "runs": runs,
        "drops": drops,
        "within": within,
        "latency": latency,
        "planned": planned,
        "outcomes": outcomes,
    }


def identical(a: Path, b: Path, executor: str, condition: str) -> tuple[int, int]:
    """(bit-identical, compared) runs of the two trees' copies of the same trials."""
    same = compared = 0
    for trial in sorted(a.iterdir()):
        fa = execution_folder(trial, executor, condition) / "sim.npz"
        fb = execution_folder(b / trial.name, executor, condition) / "sim.npz"
        if fa.exists() and fb.exists():
            za, zb = np.load(fa), np.load(fb)
            keys = set(za.files) & set(zb.files)
            same += all(za[k].shape == zb[k].shape and np.array_equal(za[k], zb[k]) for k in keys)
            compared += 1
    return same, compared


def quantiles(values: list[float]) -> str:
    if not values:
        return "-"
    return f"{np.median(values):.3f} / {np.percentile(values, 95):.3f} / {np.max(values):.3f} s"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweep", type=Path, help="a sweep folder whose trials hold plans")
    parser.add_argument("--out", type=Path, required=True, help="where each tree's copy of the plans and runs go")
    parser.add_argument("--compare", type=Path, required=True, metavar="TREE", help="the other tree (a checkout)")
    parser.add_argument("--stages", nargs="+", default=DEFAULT_STAGES, metavar="EXECUTOR:CONDITION")
    parser.add_argument("--goals", type=int, default=None, help="the first N trials only")
    parser.add_argument("--trials", type=int, nargs="+", default=None, metavar="I", help="these trials only (0-59)")
    args = parser.parse_args()
    trees = {
        "this": (HERE, copy_plans(args.sweep, args.out / "this", HERE, args.goals, args.trials)),
        "other": (
            args.compare.resolve(),
            copy_plans(args.sweep, args.out / "other", args.compare.resolve(), args.goals, args.trials),
        ),
    }
    print(f"this: {HERE}; other: {trees['other'][0]}; load average {os.getloadavg()[0]:.2f}", flush=True)
    for stage in args.stages:
        executor, condition = stage.split(":")
        run_stage(trees, executor, condition)
        same, compared = identical(trees["other"][1], trees["this"][1], executor, condition)
        print(f"{executor} {condition}: {same} of {compared} runs bit-identical between the trees", flush=True)
        for name, (_, trials) in trees.items():
            s = summary(trials, executor, condition)
            print(f"  {name}: {s['runs']} runs, dropped {len(s['drops'])} {s['drops']}, within 3 deg {s['within']}")
            if s["latency"]:
                print(
                    f"    {len(s['latency'])} replans {s['outcomes']}; latency median / p95 / max: every replan "
                    f"{quantiles(s['latency'])}, with a new plan ({len(s['planned'])}) {quantiles(s['planned'])}"
                )
        print(f"  load average {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
