"""The executions of a sweep in space in its report (issue #37 item 5): one row per (method, executor, world) with
the field's two success criteria (no drop and within 15 deg, within 0.4 rad of the plan's end), the drops, the
mean final orientation (deg) and position (mm) errors of the held runs and the executed plans' planning time
(`space_execution_summary`, `space_execution_markdown`); and the final orientation error of each goal in each world
(`figure_final_errors`), where one reads which goals fail where better than in a table.

A trial's own run (`sweep --simulate`: its sim.json, the grasp controller open loop in the plan's world) counts as
its `grasp` execution in `nominal` unless the execution folder of that pair holds one (the same run, copied there
by executions._reuse_sweep_simulation).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from trajectotree.experiments.conditions import SPACE_CONDITIONS
from trajectotree.experiments.execution_report import EXECUTORS
from trajectotree.experiments.executions import collect_executions, read_execution
from trajectotree.experiments.sweep_store import TRIALS_DIR
from trajectotree.io import SIM_JSON

# rad, sim.json's success criteria (execution.space_run.SUCCESS_ANGLES, a module that imports Drake: this one does
# not), with the label of each
CRITERIA = (("within_15deg", "within 15 deg", math.radians(15.0)), ("within_0p4rad", "within 0.4 rad", 0.4))


def space_records(sweep_dir: str | Path, rows: list[dict]) -> list[dict]:
    """Every finished execution of the sweep's trials (executions.collect_executions) and each trial's own run
    where it is not among them, as (grasp, nominal); each with the trial's planning time."""
    records = collect_executions(sweep_dir, rows)
    listed = {(r["key"], r["controller"], r["condition"]) for r in records}
    for row in rows:
        folder = Path(sweep_dir) / TRIALS_DIR / row["key"]
        if row.get("simulated") and (row["key"], "grasp", "nominal") not in listed and (folder / SIM_JSON).is_file():
            run = read_execution(folder)
            records.append(
                {**run, "key": row["key"], "method": row["method"], "goal": row["goal"], "folder": str(folder)}
                | {"controller": run.get("executor", "grasp"), "condition": "nominal"}
            )
    times = {row["key"]: row.get("total_time_s") for row in rows}
    goal_index = {row["key"]: row["goal_index"] for row in rows}
    return [r | {"total_time_s": times.get(r["key"]), "goal_index": goal_index[r["key"]]} for r in records]


def _order(names, name) -> int:
    return names.index(name) if name in names else len(names)


def _mean(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def space_execution_summary(records: list[dict], methods: list[str]) -> list[dict]:
    """One row per (method, executor, world), in the order of `methods`, SPACE_CONDITIONS and the executors: how
    many executed, dropped, met each criterion; the mean final orientation error (deg) and position error (mm)
    over the runs without a drop (a dropped cube's lies where it fell) and the mean planning time of the plans."""
    keys = sorted(
        {(r["method"], r["controller"], r["condition"]) for r in records},
        key=lambda k: (_order(methods, k[0]), _order(SPACE_CONDITIONS, k[2]), k[2], _order(EXECUTORS, k[1])),
    )
    table = []
    for method, executor, condition in keys:
        mine = [r for r in records if (r["method"], r["controller"], r["condition"]) == (method, executor, condition)]
        held = [r for r in mine if not r["dropped"]]
        table.append(
            {
                "method": method,
                "executor": executor,
                "condition": condition,
                "executed": len(mine),
                "dropped": sum(bool(r["dropped"]) for r in mine),
                **{name: sum(bool(r.get(name)) for r in mine) for name, _, _ in CRITERIA},
                "held": len(held),
                "mean_final_orientation_error_deg": _mean([r["final_orientation_error_deg"] for r in held]),
                "mean_final_position_error_mm": _mean([1e3 * r["final_position_error_m"] for r in held]),
                "mean_planning_time_s": _mean([r["total_time_s"] for r in mine]),
            }
        )
    return table


def _fmt(value, spec: str) -> str:
    return "n/a" if value is None else f"{value:{spec}}"


def space_execution_markdown(table: list[dict], labels: dict[str, str]) -> str:
    lines = [
        "| method | executor | world | executed | dropped | within 15 deg | within 0.4 rad "
        "| final orientation error [deg] | final position error [mm] | planning time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in table:
        n = s["executed"]
        lines.append(
            f"| {labels.get(s['method'], s['method'])} | {s['executor']} | {s['condition']} | {n} | "
            f"{s['dropped']} ({s['dropped'] / n:.0%}) | {s['within_15deg']}/{n} | {s['within_0p4rad']}/{n} | "
            f"{_fmt(s['mean_final_orientation_error_deg'], '.2f')} | {_fmt(s['mean_final_position_error_mm'], '.2f')} "
            f"| {_fmt(s['mean_planning_time_s'], '.2f')} |"
        )
    return "\n".join(lines) + "\n"


SPACE_EXECUTION_NOTES = """
Each plan executed in Drake's full dynamics per executor (`grasp`: the grasp controller open loop;
`grasp-closed-loop`: with the closed loop) and world (`nominal`: the plan's; `mismatch`: friction 0.55 and the
cube's mass +20 % in the simulated plant only; `push`: 0.2 N along +x on the cube's centre for 0.2 s in the
middle of the plan's middle segment; `friction-0.4`: friction 0.4, the plans' 0.7; `mass-x1.5`: the cube 50 %
heavier; `push-1N`: 1 N along +x (horizontal), timed like `push`); the controller keeps the plan's values.
Within 15 deg / 0.4 rad: no drop (the cube's centre never sim.drop_distance, 5 cm, off the plan's) and the
final orientation that close to the plan's last one (its goal, within 2 deg, where it planned). Final errors:
means over the runs without a drop, against the plan's last pose after its hold. Planning time: mean over the
executed plans.
fig_final_error shows each goal's final orientation error per world (a cross: a drop).
"""


def figure_final_errors(records: list[dict], methods: list[str], labels: dict[str, str]):
    """The final orientation error (deg, log scale) of each goal in each (executor, world), a cross for a drop,
    with the two criteria as lines: one panel per method."""
    import matplotlib.pyplot as plt

    methods = [m for m in methods if any(r["method"] == m for r in records)]
    series = sorted(
        {(r["controller"], r["condition"]) for r in records},
        key=lambda k: (_order(SPACE_CONDITIONS, k[1]), k[1], _order(EXECUTORS, k[0])),
    )
    goals = sorted({r["goal_index"] for r in records})
    fig, axes = plt.subplots(len(methods), 1, figsize=(max(6.0, 0.3 * len(goals) + 3), 3.8 * len(methods)))
    axes = np.atleast_1d(axes)
    colors = plt.get_cmap("tab10")
    width = 0.7 / len(series)  # goal indices apart by 1: each series beside the others within a goal's slot
    for ax, method in zip(axes, methods):
        for j, (executor, condition) in enumerate(series):
            mine = [
                r for r in records if (r["method"], r["controller"], r["condition"]) == (method, executor, condition)
            ]
            for dropped, marker in ((False, "o"), (True, "x")):
                chosen = [r for r in mine if bool(r["dropped"]) == dropped]
                ax.scatter(
                    [r["goal_index"] - 0.35 + (j + 0.5) * width for r in chosen],
                    [max(r["final_orientation_error_deg"], 1e-2) for r in chosen],  # deg: the log axis' floor
                    marker=marker,
                    color=colors(j % 10),
                    s=22,
                    label=None if dropped else f"{executor}, {condition}",
                )
        for _, label, angle in CRITERIA:
            ax.axhline(math.degrees(angle), color="0.4", lw=0.8, ls="--" if "deg" in label else ":")
            ax.text(ax.get_xlim()[1], math.degrees(angle), f" {label}", fontsize=7, va="center", color="0.3")
        ax.set_yscale("log")
        ax.set_xticks(goals)
        ax.set_xlabel("goal index")
        ax.set_ylabel("final orientation error [deg]")
        ax.set_title(
            f"{labels.get(method, method)}: final orientation error per goal and world (x: dropped)", fontsize=9
        )
        ax.grid(alpha=0.3, which="both", axis="y")
        # below the panel: above it the drops lie near 180 deg
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.28), ncol=min(len(series), 4), frameon=False)
    fig.tight_layout()
    return fig
