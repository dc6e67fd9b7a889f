"""The report of a sweep's executions: one row per (method, condition, executor) with drops, errors
and replans (`execution_summary`, `execution_markdown`), and every replan that gave no plan
(`refused_replans`, `refused_markdown`).
"""

from __future__ import annotations

import numpy as np

from trajectotree.config.executor import Executor
from trajectotree.experiments.conditions import CONDITIONS
from trajectotree.results import FINAL_THETA_TOLERANCE  # rad, "final orientation held" in the execution table

# The executors of the tables, in their order (a condition's open loop, closed loop and replanning together).
EXECUTORS = tuple(e.value for e in (Executor.GRASP, Executor.GRASP_CLOSED_LOOP, Executor.GRASP_REPLAN, Executor.PAPER))


def execution_summary(records: list[dict], methods: list[str]) -> list[dict]:
    """One row per (method, condition, executor), in the order of `methods`, CONDITIONS and EXECUTORS
    (so a condition's open loop, closed loop and replanning rows stand together): executions, drops,
    mean absolute errors, the mean final error and how many ended within 3 deg of the planned final
    orientation; replans, how many gave a new plan, and their latency's median and 95th percentile."""

    def order(names, name) -> int:
        return names.index(name) if name in names else len(names)

    keys = sorted(
        {(r["method"], r["controller"], r["condition"]) for r in records},
        key=lambda k: (order(methods, k[0]), order(CONDITIONS, k[2]), k[2], order(EXECUTORS, k[1])),
    )
    table = []
    for method, controller, condition in keys:
        mine = [r for r in records if (r["method"], r["controller"], r["condition"]) == (method, controller, condition)]

        def mean(values) -> float:
            return float(np.mean(values))

        replans = [e for r in mine for e in r.get("replans") or ()]
        latency = [e["latency_s"] for e in replans]
        table.append(
            {
                "method": method,
                "controller": controller,
                "condition": condition,
                "executed": len(mine),
                "dropped": sum(bool(r["dropped"]) for r in mine),
                "mae_x": mean([r["mae_x"] for r in mine]),
                "mae_y": mean([r["mae_y"] for r in mine]),
                "mae_theta": mean([r["mae_theta"] for r in mine]),
                "final_x": mean([abs(r["final_error"][0]) for r in mine]),
                "final_y": mean([abs(r["final_error"][1]) for r in mine]),
                "final_theta": mean([abs(r["final_error"][2]) for r in mine]),
                "final_theta_within_3deg": sum(abs(r["final_error"][2]) <= FINAL_THETA_TOLERANCE for r in mine),
                "replans": len(replans),
                "new_plans": sum(bool(e.get("planned")) for e in replans),
                "latency_median_s": float(np.median(latency)) if latency else None,
                "latency_p95_s": float(np.percentile(latency, 95)) if latency else None,
            }
        )
    return table


def execution_markdown(table: list[dict], labels: dict[str, str]) -> str:
    lines = [
        "| method | controller | condition | executed | dropped | MAE x [mm] | MAE y [mm] | MAE theta [rad] "
        "| final error x / y [mm], theta [rad] | final theta within 3 deg | replans (new plans) "
        "| latency median / p95 [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in table:
        latency = "-"
        if s["latency_median_s"] is not None:
            latency = f"{s['latency_median_s']:.3f} / {s['latency_p95_s']:.3f}"
        lines.append(
            f"| {labels.get(s['method'], s['method'])} | {s['controller']} | {s['condition']} | "
            f"{s['executed']} | {s['dropped']} ({s['dropped'] / s['executed']:.0%}) | "
            f"{1e3 * s['mae_x']:.2f} | {1e3 * s['mae_y']:.2f} | {s['mae_theta']:.3f} | "
            f"{1e3 * s['final_x']:.2f} / {1e3 * s['final_y']:.2f}, {s['final_theta']:.3f} | "
            f"{s['final_theta_within_3deg']}/{s['executed']} | "
            + (f"{s['replans']} ({s['new_plans']})" if s["replans"] else "-")
            + f" | {latency} |"
        )
    return "\n".join(lines) + "\n"


def refused_replans(records: list[dict]) -> list[dict]:
    """Every replan that gave no plan, per execution (method, goal, condition): when, the outcome
    (sim.json's replans' outcome: no_plan, search_deadline, start_refused, first_segment_failed, late) and the
    planner's reason, ordered by method, condition and goal."""
    rows = [
        {
            "method": r["method"],
            "goal": r["goal"],
            "controller": r["controller"],
            "condition": r["condition"],
            "time_s": e["time_s"],
            "mu": e["mu"],
            "outcome": e.get("outcome", "unknown"),
            "status": e.get("status", ""),
        }
        for r in records
        for e in r.get("replans") or ()
        if not e.get("planned")
    ]
    return sorted(
        rows,
        key=lambda row: (
            row["method"],
            CONDITIONS.index(row["condition"]) if row["condition"] in CONDITIONS else len(CONDITIONS),
            row["goal"],
            row["time_s"],
        ),
    )


def refused_markdown(rows: list[dict], labels: dict[str, str]) -> str:
    """The replans without a plan, per goal: the search's (or the start's) reason, as a person reads it."""
    lines = [
        "| method | goal [rad] | condition | at [s] | friction estimate | outcome | reason |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        reason = row["status"].replace("|", "/")
        lines.append(
            f"| {labels.get(row['method'], row['method'])} | {row['goal']:+.3f} | {row['condition']} | "
            f"{row['time_s']:.2f} | {row['mu']:.3f} | {row['outcome'].replace('_', ' ')} | {reason} |"
        )
    return "\n".join(lines) + "\n"
