"""`trajectotree plan --goal RAD` (or --goal-pose X Y THETA): plan a rotation of the object (the
box, or any convex polygon: --polygon), or its move to a pose, with TrajectoTree or a CITO
baseline; writes DIR/plan.npz (the trajectory at every knot) and DIR/plan.json (the solve
report, the contact sequence and the config). A plan that does not converge is still written, with "success": false and
IPOPT's status (exit code 0)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from trajectotree.cli import resume_collector
from trajectotree.cli.common import (
    HTML_SUFFIXES,
    add_config_options,
    add_goal_options,
    check_executable_hand,
    check_output_dir,
    check_output_file,
    config_from_args,
    goal_from_args,
    plan_request_from_args,
    print_json,
    reason_lines,
)
from trajectotree.cli.progress import ipopt_progress
from trajectotree.cli.progress import wanted as progress_wanted
from trajectotree.cli.space_goal import add_space_goal_options, refuse_space_goal_on_planar_hand, space_goal
from trajectotree.io import PLAN_JSON, PLAN_NPZ, SIM_JSON, SIM_NPZ
from trajectotree.results import METHODS, check_method

# Files derived from a plan (by `simulate`): stale once a new plan replaces it.
DERIVED_FILES = (SIM_JSON, SIM_NPZ)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "plan",
        help="plan a rotation of the object, a box or any convex polygon, or a move to a pose "
        "(contact search + trajectory optimization)",
        description=__doc__,
    )
    add_goal_options(p)
    add_space_goal_options(p)
    p.add_argument(
        "--method",
        default="trajectotree",
        metavar="METHOD",
        help=f"planner (default: trajectotree; valid: {', '.join(METHODS)})",
    )
    add_config_options(p, formulation=True, space=True)
    p.add_argument(
        "--start",
        metavar="FILE.json",
        help="plan from this measured state (object pose and velocity, joint angles, optional contacts; "
        "`trajectotree state` writes one from a run); --goal is then the final orientation in W, "
        "--goal-pose the final pose",
    )
    p.add_argument(
        "--segment-workers",
        type=int,
        metavar="W",
        help="local processes solving the keyframes "
        "formulation's segments (default: one per segment, at most one per core; 1: serially)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="output folder (default: plan_<method>_<goal>); a previous plan's sim.json and sim.npz there are "
        "removed, as they belong to the plan this one replaces; while planning the command holds DIR/.lock, so no "
        "`simulate`, `demo` or other `plan` works in DIR meanwhile",
    )
    p.add_argument("--json", action="store_true", help="print plan.json to stdout")
    p.add_argument("--html", metavar="FILE", help="write a self-contained Meshcat playback of the planned trajectory")
    # resumes the collector after its start-up (the imports, the scene, the checks), in run and run_space
    p.set_defaults(run=run, resumes_collector=True)


def run(args) -> int:
    from trajectotree.io import folder_lock, load_start
    from trajectotree.planning.piece import worker_scene
    from trajectotree.planning.segment_pool import check_workers
    from trajectotree.scene.spatial import is_space_hand
    from trajectotree.search.initial_grasp import GraspTables

    if args.hand is not None and is_space_hand(args.hand):
        return run_space(args)
    refuse_space_goal_on_planar_hand(args)
    method = check_method(args.method)
    config = config_from_args(args)
    goal = goal_from_args(args, config)
    workers = check_workers(args.segment_workers, "--segment-workers")
    out = check_output_dir("--out", args.out or default_out(method, goal), (PLAN_JSON, PLAN_NPZ))
    if args.html:  # it may go into --out, which save_plan creates before the playback is written
        check_output_file("--html", args.html, HTML_SUFFIXES, created=(out,))
    start = load_start(args.start) if args.start else None
    # The scene the segment workers solve in too: they fork from this process and inherit it, where
    # a scene of its own for them would be built a second time (~0.05 s, issue 35).
    scene = worker_scene(config.scene)
    if args.html:
        check_executable_hand(scene, "--html's playback")
    # The initial grasps the checks rank, kept for the search (ranking them again costs ~0.04 s, issue 35).
    tables = GraspTables()
    # refused here, before any planning, when the start or the object cannot be planned from (tt.plan's checks)
    request = plan_request_from_args(
        args, scene, config, goal, method=method, start=start, segment_workers=workers, grasp_tables=tables
    )
    resume_collector()
    with folder_lock(out, "--out", "trajectotree plan"):  # no `simulate` or other `plan` writes there meanwhile
        return plan_into(args, request, out, tables)


def plan_into(args, request, out: Path, tables) -> int:
    """Plans the checked request, with the initial grasps its checks ranked (GraspTables), and writes
    it into `out`, whose lock this command holds."""
    from trajectotree.io import plan_to_json, save_plan
    from trajectotree.planning.planners import plan_request

    method, goal, config = request.method, request.goal, request.config
    result = plan_request(request, grasp_tables=tables, log_observer=ipopt_progress(progress_wanted(args)))
    removed = remove_derived_files(out)
    save_plan(result, out)
    if removed:
        print(f"removed {', '.join(removed)} from {out}: they belonged to the plan this one replaces", file=sys.stderr)
    if args.html and result.trajectory is not None:
        from trajectotree.execution.playback import write_plan_html

        write_plan_html(result, config, args.html)
    if args.json:
        print_json(plan_to_json(result))
        return 0
    v = ", ".join(f"{k} {val:.1e}" for k, val in result.violations.items())
    status, details = reason_lines(result.status)
    where = "" if goal.position is None else f" at ({goal.position[0]:+.4f}, {goal.position[1]:+.4f}) m"
    print(
        f"{method}: goal {goal.theta:+.3f} rad{where}, N = {result.config.search.num_nodes}, "
        f"{'succeeded' if result.success else 'FAILED'} ({status}), "
        f"{result.iterations} iterations, cost {result.cost:.4g}"
    )
    for line in details:
        print(f"  {line}")
    print(
        f"time: search {result.search_time_s:.2f} s, build {result.build_time_s:.2f} s, "
        f"solve {result.solve_time_s:.2f} s, total {result.total_time_s:.2f} s"
    )
    if result.trajectory is not None:
        x = result.trajectory.x[-1]
        print(f"final pose: x {x[0]:+.4f} m, y {x[1]:+.4f} m, theta {x[2]:+.4f} rad; max violations: {v}")
    print(f"wrote {out}/plan.json and {out}/plan.npz")
    return 0


def default_out(method: str, goal) -> str:
    """plan_<method>_<theta>, and _<x>_<y> for a goal with a position."""
    where = "" if goal.position is None else f"_{goal.position[0]:+.3f}_{goal.position[1]:+.3f}"
    return f"plan_{method}_{goal.theta:+.3f}{where}"


def remove_derived_files(out: Path) -> list[str]:
    """Removes a previous plan's simulation results from `out`; returns their names."""
    removed = []
    for name in DERIVED_FILES:
        if (out / name).is_file():
            (out / name).unlink()
            removed.append(name)
    return removed


# -- a hand in space ------------------------------------------------------------------------------
def run_space(args) -> int:
    """`trajectotree plan` for a hand in space: the contact search and the keyframes programs in space, written as
    plan.npz and plan.json (trajectotree.planning.spatial)."""
    from trajectotree.cli.space_options import build_args_scene, check_space_graspable, space_config
    from trajectotree.io import folder_lock
    from trajectotree.planning.segment_pool import check_workers
    from trajectotree.planning.spatial import plan_space, plan_space_cito, save_space_plan

    resume_collector()  # at once: a plan in space has its start-up with the collector (not measured, issue 35)
    goal = space_goal(args)
    workers = check_workers(args.segment_workers, "--segment-workers")
    method = check_method(args.method)
    config = space_config(args)
    w, x, y, z = goal
    default = f"plan_space_{'' if method == 'trajectotree' else method + '_'}{w:+.3f}_{x:+.3f}_{y:+.3f}_{z:+.3f}"
    out = check_output_dir("--out", args.out or default, (PLAN_JSON, PLAN_NPZ))
    if args.html:  # it may go into --out, which save_space_plan creates before the playback is written
        check_output_file("--html", args.html, HTML_SUFFIXES, created=(out,))
    scene = build_args_scene(args, config)
    check_space_graspable(scene, config, args)
    start = space_start(args, scene, config, method)
    with folder_lock(out, "--out", "trajectotree plan"):
        if method == "trajectotree":
            result = plan_space(scene, goal, config, workers, start)
        else:
            result = plan_space_cito(scene, goal, config, method, workers)
        removed = remove_derived_files(out)
        save_space_plan(result, out, config)
        if args.html and result.trajectory is not None:
            from trajectotree.execution.playback import write_space_plan_html

            write_space_plan_html(
                scene,
                result.trajectory.arrays(),
                args.html,
                title=f"{'TrajectoTree' if method == 'trajectotree' else method}: {out.name}",
            )
    if removed:
        print(f"removed {', '.join(removed)} from {out}: they belonged to the plan this one replaces", file=sys.stderr)
    if args.json:
        print_json(result.to_json())
        return 0
    status, details = reason_lines(result.status)
    print(
        f"{method} in space: goal quaternion [{w:+.4f}, {x:+.4f}, {y:+.4f}, {z:+.4f}], "
        f"{len(result.contact_plan.nodes)} nodes, {'succeeded' if result.success else 'FAILED'} ({status})"
    )
    for line in details:
        print(f"  {line}")
    print(
        f"time: {'search' if method != 'cito-warm' else 'TrajectoTree (warm start)'} {result.search_time_s:.2f} s, "
        f"{'segments' if result.formulation == 'keyframes' else 'program'} {result.solve_time_s:.2f} s, "
        f"total {result.total_time_s:.2f} s"
    )
    if result.physics_check is not None:
        c = result.physics_check
        print(
            f"final orientation {np.degrees(result.final_error_rad):.3f} deg from the goal; physics check "
            f"{'passed' if c.passed else 'FAILED'}: Newton-Euler {c.newton_euler_force_N:.1e} N, "
            f"{c.newton_euler_moment_Nm:.1e} N m, cones {c.friction_cone_N:.1e} N"
        )
    print(f"wrote {out}/plan.json" + (f" and {out}/plan.npz" if result.trajectory is not None else ""))
    if args.html:
        print(f"playback: {args.html}" if result.trajectory is not None else "playback: not written (no trajectory)")
    return 0


def space_start(args, scene, config, method: str):
    """--start's SpaceStartState, checked against the scene before any planning (planning.start.space_start_root:
    StartRefused, exit 2, naming the finger or joint, the value and the limit), or None without --start."""
    from trajectotree.config import ConfigError
    from trajectotree.io import load_start
    from trajectotree.planning.start import space_start_root

    if args.start is None:
        return None
    if method != "trajectotree":
        raise ConfigError(
            field="--method",
            value=method,
            problem="plans a hand in space from the hand's initial grasp only",
            valid="--method trajectotree with --start (its search roots at the start's grasp)",
            label="valid",
        )
    start = load_start(args.start, space=True)
    space_start_root(scene, start, config)
    return start
