"""`trajectotree demo`: the whole pipeline on the paper's default job, in one command.

Plans a pi/2 rotation of the 0.20 x 0.10 m, 50 g box (or of the object --box-size, --polygon
and --mass describe) with TrajectoTree (contact-sequence search, then the plan-constrained
CITO solved with IPOPT), executes the plan in a full-dynamics Drake simulation with the
configured controller (sim.controller: the object-level grasp controller by default, or the
paper's eq. 20), and writes into --out:
plan.json + plan.npz (the plan), sim.json + sim.npz (the run and its tracking errors),
keyframes.png (the contact sequence), playback.html (Meshcat playback of the run, opens
offline in any browser), forces.png (each finger's simulated vs planned force on the object)
and summary.json (the numbers printed at the end).

With a hand in space (--hand fingerpro4) it turns the cube a quarter turn about the horizontal x axis
(--goal-rpy 1.5708 0 0, or the goal --goal-rpy or --goal-quat give), executes the plan open loop with
the grasp controller in space and writes the same files, and run.gif (the run on 3D axes).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from trajectotree.cli.common import (
    add_config_options,
    check_executable_hand,
    check_output_dir,
    config_from_args,
    plan_request_from_args,
    print_json,
)
from trajectotree.cli.progress import ipopt_progress
from trajectotree.cli.progress import wanted as progress_wanted
from trajectotree.cli.space_goal import add_space_goal_options, refuse_space_goal_on_planar_hand, space_goal
from trajectotree.io import PLAN_JSON, PLAN_NPZ, SIM_JSON, SIM_NPZ
from trajectotree.results import check_goal, outcome_text

KEYFRAMES = "keyframes.png"
PLAYBACK = "playback.html"
FORCES = "forces.png"
SUMMARY = "summary.json"
GIF = "run.gif"  # in space only: the plane's README GIF is made by scripts, not by the demo
# Written only when planning gets that far: removed first, so a rerun into the same
# folder never leaves an older run's files beside the new plan.
DERIVED_FILES = (SIM_JSON, SIM_NPZ, KEYFRAMES, PLAYBACK, FORCES, SUMMARY, GIF)
SPACE_GOAL_RPY = (1.5708, 0.0, 0.0)  # rad, a hand in space's default goal: a quarter turn about the horizontal x


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="plan, simulate and play back a pi/2 rotation (start here)", description=__doc__
    )
    p.add_argument(
        "--out",
        default="demo",
        metavar="DIR",
        help="output directory (default: ./demo); the demo holds DIR/.lock while it runs, so no `plan` or "
        "`simulate` works in DIR meanwhile",
    )
    p.add_argument("--meshcat", action="store_true", help="also watch the run live in Meshcat on localhost")
    p.add_argument(
        "--goal",
        type=float,
        metavar="RAD",
        help="goal orientation of the object, rad in W, any number within +-20 pi (default: pi/2)",
    )
    add_space_goal_options(p)  # default for a hand in space: --goal-rpy 1.5708 0 0
    p.add_argument("--json", action="store_true", help="print summary.json instead of the text summary")
    add_config_options(p, formulation=True, space=True)
    p.set_defaults(run=run)


def plan_summary(result) -> dict:
    keys = (
        "method",
        "goal",
        "success",
        "converged",
        "status",
        "search_time_s",
        "build_time_s",
        "solve_time_s",
        "total_time_s",
        "iterations",
    )
    summary = {k: getattr(result, k) for k in keys}
    summary["cost"] = result.cost if math.isfinite(result.cost) else None
    summary["switching_fingers"] = [n.switching_finger for n in result.contact_plan.nodes]
    # keyframes: build and solve times are summed over this many programs, solved in parallel
    summary["segment_programs"] = len(result.segments)
    return summary


def print_summary(summary: dict, out: Path, noun: str) -> None:
    """The text summary; `noun` names the object in the simulation line (playback_page.object_noun).
    Each time says what it is: wall-clock time, or process time summed over the keyframes'
    segment programs (which run in parallel, so their sum may exceed the total)."""
    from trajectotree.cli.common import reason_lines

    p, s = summary["plan"], summary["simulation"]
    switches = " ".join("-" if f is None else str(f) for f in p["switching_fingers"][1:])
    name = summary.get("object", "box")
    print(f"TrajectoTree demo: rotate the {name} by {p['goal']:+.3f} rad ({math.degrees(p['goal']):+.1f} deg)")
    print(f"  contact search  {p['search_time_s']:6.2f} s wall     switching fingers per segment: {switches or 'none'}")
    programs = p.get("segment_programs") or 0
    cito = p["build_time_s"] + p["solve_time_s"]
    status, details = reason_lines(p["status"])
    how = (
        f"summed   over its {programs} segment programs, solved in parallel: " if programs else "wall     one program: "
    )
    print(
        f"  CITO (IPOPT)    {cito:6.2f} s {how}build {p['build_time_s']:.2f} s, solve {p['solve_time_s']:.2f} s, "
        f"{p['iterations']} iterations; {status}"
    )
    for line in details:
        print(f"      {line}")
    cost = "n/a" if p["cost"] is None else f"{p['cost']:.4g}"
    verdict = (
        "converged, physics check passed"
        if p["success"]
        else "converged, but the physics check FAILED (see the status)"
        if p["converged"]
        else "NOT converged"
    )
    print(f"  total planning  {p['total_time_s']:6.2f} s wall     search and CITO: {verdict}, cost {cost}")
    if s is not None:
        print(
            f"  simulation      {s['sim_time_s']:6.2f} s wall     {s['duration_s']:.1f} s simulated, "
            f"{outcome_text(s, noun)}; "
            f"mean |error| x {1e3 * s['mae_x']:.1f} mm, y {1e3 * s['mae_y']:.1f} mm, "
            f"theta {s['mae_theta']:.3f} rad; final theta error {s['final_error'][2]:.3f} rad"
            + ("" if s.get("error_at_drop") is None else f" ({s['error_at_drop'][2]:.3f} rad at the drop)")
        )
    else:
        print("  simulation      skipped: no trajectory to execute")
    print(f"files in {out}/: " + ", ".join(summary["files"]))
    if PLAYBACK in summary["files"]:
        print(f"open {out / PLAYBACK} in a browser to watch the run (offline, any browser)")


def run(args) -> int:
    from trajectotree.io import folder_lock
    from trajectotree.scene.plant import build_scene
    from trajectotree.scene.spatial import is_space_hand

    if args.hand is not None and is_space_hand(args.hand):
        return run_space(args)
    refuse_space_goal_on_planar_hand(args)
    goal = check_goal(math.pi / 2 if args.goal is None else args.goal, "--goal")
    config = config_from_args(args)
    out = check_output_dir("--out", args.out, (PLAN_JSON, PLAN_NPZ, *DERIVED_FILES))
    scene = build_scene(config.scene)
    check_executable_hand(scene, "the demo's simulation")
    request = plan_request_from_args(args, scene, config, goal)  # tt.plan's checks, before any planning
    with folder_lock(out, "--out", "trajectotree demo"):  # no `plan` or `simulate` writes there meanwhile
        return demo_into(args, request, out)


def demo_into(args, request, out: Path) -> int:
    """Plans the checked request, executes and draws the plan, into `out`, whose lock this command holds."""
    from trajectotree.cli.search_cmd import draw_plan
    from trajectotree.cli.simulate_cmd import save_sim_json_with_plan_status
    from trajectotree.execution.meshcat_scene import start_meshcat
    from trajectotree.execution.playback_page import object_noun
    from trajectotree.execution.run import run_simulation
    from trajectotree.figures.run import figure_finger_forces, save_figure, segment_spans
    from trajectotree.io import save_plan, save_sim, write_json_atomic
    from trajectotree.planning.planners import plan_request
    from trajectotree.scene.plant import describe_object

    goal, config, scene = request.goal, request.config, request.scene
    meshcat = start_meshcat() if args.meshcat else None
    log = sys.stderr if args.json else sys.stdout
    if meshcat is not None:
        print(f"Meshcat: {meshcat.web_url()} (open it now; the run plays once the plan is ready)", file=log, flush=True)

    print(f"planning a {goal.theta:+.3f} rad rotation with TrajectoTree ...", file=log, flush=True)
    result = plan_request(request, log_observer=ipopt_progress(progress_wanted(args)))
    for name in DERIVED_FILES:  # the lock made `out` and removes it, still empty, if the plan is interrupted
        (out / name).unlink(missing_ok=True)
    save_plan(result, out)
    files = [PLAN_JSON, PLAN_NPZ]
    if result.contact_plan.success:
        draw_plan(scene, result.contact_plan, str(out / KEYFRAMES))
        files.append(KEYFRAMES)
    sim = None
    if result.trajectory is not None:
        print(f"simulating the plan with the {config.sim.controller} controller ...", file=log, flush=True)
        sim = run_simulation(plan=result, config=config, meshcat=meshcat, html_path=out / PLAYBACK)
        save_sim(sim, out)
        sim_json = save_sim_json_with_plan_status(sim, str(out), result.success)
        spans = segment_spans(
            [n.switching_finger for n in result.contact_plan.nodes], config.cito.knots_per_segment, config.cito.dt
        )
        save_figure(figure_finger_forces(sim, spans, goal=goal), out / FORCES)
        files += [SIM_JSON, SIM_NPZ, PLAYBACK, FORCES]
    summary = {
        "object": describe_object(config.scene),
        "plan": plan_summary(result),
        "simulation": None if sim is None else sim_json,
        "files": files + [SUMMARY],
    }
    write_json_atomic(out / SUMMARY, summary)
    if args.json:
        print_json(summary)
    else:
        print_summary(summary, out, object_noun(config.scene))
    if meshcat is not None and sys.stdin.isatty():
        input("Meshcat shows the recording; press Enter to exit. ")
    return 0


# -- a hand in space ------------------------------------------------------------------------------
def run_space(args) -> int:
    """The demo with a hand in space: every input checked (the goal, the config, the executor, the folder)
    before planning."""
    from pydrake.math import RollPitchYaw

    from trajectotree.cli.space_options import build_args_scene, check_space_graspable, space_config
    from trajectotree.config import ConfigError
    from trajectotree.config.executor import Executor
    from trajectotree.execution.space_run import SPACE_EXECUTORS
    from trajectotree.io import folder_lock

    given = any(getattr(args, name) is not None for name in ("goal", "goal_quat", "goal_rpy"))
    goal = space_goal(args) if given else RollPitchYaw(SPACE_GOAL_RPY).ToQuaternion().wxyz()
    config = space_config(args)
    if Executor(config.sim.controller) not in SPACE_EXECUTORS:
        raise ConfigError(
            field="sim.controller",
            value=config.sim.controller,
            problem="does not execute plans in space yet",
            choices=tuple(e.value for e in SPACE_EXECUTORS),
        )
    out = check_output_dir("--out", args.out, (PLAN_JSON, PLAN_NPZ, *DERIVED_FILES))
    scene = build_args_scene(args, config)
    check_space_graspable(scene, config, args)
    with folder_lock(out, "--out", "trajectotree demo"):  # no `plan` or `simulate` writes there meanwhile
        return space_demo_into(args, scene, goal, config, out)


def space_demo_into(args, scene, goal, config, out: Path) -> int:
    """Plans the turn to `goal` (a unit quaternion) of the cube of `scene`, executes the plan and draws it, into
    `out`, whose lock this command holds."""
    from trajectotree.cli.search_cmd import draw_plan
    from trajectotree.cli.space_simulate import save_space_sim, write_space_gif
    from trajectotree.execution.meshcat_scene import start_meshcat
    from trajectotree.execution.space_control import SpaceReference
    from trajectotree.execution.space_run import simulate_space
    from trajectotree.figures.run import figure_finger_forces, save_figure
    from trajectotree.io import write_json_atomic
    from trajectotree.planning.spatial import plan_space, save_space_plan

    meshcat = start_meshcat() if args.meshcat else None
    log = sys.stderr if args.json else sys.stdout
    if meshcat is not None:
        print(f"Meshcat: {meshcat.web_url()} (open it now; the run plays once the plan is ready)", file=log, flush=True)
    print(f"planning a {quaternion_degrees(goal):.1f} deg turn of the cube with TrajectoTree ...", file=log, flush=True)
    result = plan_space(scene, goal, config)
    for name in DERIVED_FILES:  # the lock made `out` and removes it, still empty, if the plan is interrupted
        (out / name).unlink(missing_ok=True)
    save_space_plan(result, out, config)
    files = [PLAN_JSON] + ([PLAN_NPZ] if result.trajectory is not None else [])
    if result.contact_plan.success:
        draw_plan(scene, result.contact_plan, str(out / KEYFRAMES))
        files.append(KEYFRAMES)
    sim = None
    if result.trajectory is not None:
        print("simulating the plan with the grasp controller in space ...", file=log, flush=True)
        reference = SpaceReference.from_arrays(result.trajectory.arrays())
        run = simulate_space(reference, config, scene, meshcat=meshcat, html_path=out / PLAYBACK)
        sim = save_space_sim(run, out, result.success)
        save_figure(figure_finger_forces(run, goal=list(result.goal), noun="cube"), out / FORCES)
        write_space_gif(run, reference, scene, out / GIF)
        files += [SIM_JSON, SIM_NPZ, PLAYBACK, FORCES, GIF]
    summary = {"object": "cube", "plan": space_plan_summary(result), "simulation": sim, "files": files + [SUMMARY]}
    write_json_atomic(out / SUMMARY, summary)
    if args.json:
        print_json(summary)
    else:
        print_space_summary(summary, out)
    if meshcat is not None and sys.stdin.isatty():
        input("Meshcat shows the recording; press Enter to exit. ")
    return 0


def quaternion_degrees(quaternion) -> float:
    """deg, the angle of the rotation of a unit quaternion [w, x, y, z]."""
    return math.degrees(2 * math.acos(min(abs(float(quaternion[0])), 1.0)))


def space_plan_summary(result) -> dict:
    """The numbers of a plan in space the demo prints and keeps in summary.json."""
    check = result.physics_check
    return {
        "method": result.method,
        "goal_quaternion": [float(v) for v in result.goal],
        "success": result.success,
        "status": result.status,
        "search_time_s": result.search_time_s,
        "solve_time_s": result.solve_time_s,
        "total_time_s": result.total_time_s,
        "final_error_rad": result.to_json()["final_error_rad"],
        "physics_check_passed": None if check is None else bool(check.passed),
        "switching_fingers": [n.switching_finger for n in result.contact_plan.nodes],
        "segment_programs": len(result.segments),
    }


def print_space_summary(summary: dict, out: Path) -> None:
    """The text summary of the demo in space, as the plane's (print_summary): each time wall-clock."""
    from trajectotree.cli.common import reason_lines

    p, s = summary["plan"], summary["simulation"]
    w, x, y, z = p["goal_quaternion"]
    switches = " ".join("-" if f is None else str(f) for f in p["switching_fingers"][1:])
    print(
        f"TrajectoTree demo in space: turn the cube by {quaternion_degrees(p['goal_quaternion']):.1f} deg "
        f"(goal quaternion [{w:+.4f}, {x:+.4f}, {y:+.4f}, {z:+.4f}])"
    )
    print(f"  contact search  {p['search_time_s']:6.2f} s wall     switching fingers per segment: {switches or 'none'}")
    status, details = reason_lines(p["status"])
    print(
        f"  CITO (IPOPT)    {p['solve_time_s']:6.2f} s wall     its {p['segment_programs']} segment programs; {status}"
    )
    for line in details:
        print(f"      {line}")
    check = {True: "physics check passed", False: "physics check FAILED", None: "no physics check"}
    error = "" if p["final_error_rad"] is None else f", {math.degrees(p['final_error_rad']):.3f} deg from the goal"
    print(
        f"  total planning  {p['total_time_s']:6.2f} s wall     "
        f"{'succeeded' if p['success'] else 'FAILED'}: {check[p['physics_check_passed']]}{error}"
    )
    if s is not None:
        outcome = f"DROPPED at {s['drop_time_s']:.2f} s" if s["dropped"] else "held"
        print(
            f"  simulation      {s['sim_time_s']:6.2f} s wall     {s['duration_s']:.1f} s simulated, {outcome}; final "
            f"orientation error {s['final_orientation_error_deg']:.2f} deg, position error "
            f"{1e3 * s['final_position_error_m']:.2f} mm (largest on the way "
            f"{math.degrees(s['max_orientation_error_rad']):.2f} deg, {1e3 * s['max_position_error_m']:.2f} mm)"
        )
    else:
        print("  simulation      skipped: no trajectory to execute")
    print(f"files in {out}/: " + ", ".join(summary["files"]))
    if PLAYBACK in summary["files"]:
        print(f"open {out / PLAYBACK} in a browser to watch the run (offline, any browser)")
