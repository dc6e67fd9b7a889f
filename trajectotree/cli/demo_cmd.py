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
from trajectotree.io import PLAN_JSON, PLAN_NPZ, SIM_JSON, SIM_NPZ
from trajectotree.results import check_goal, outcome_text

KEYFRAMES = "keyframes.png"
PLAYBACK = "playback.html"
FORCES = "forces.png"
SUMMARY = "summary.json"
# Written only when planning gets that far: removed first, so a rerun into the same
# folder never leaves an older run's files beside the new plan.
DERIVED_FILES = (SIM_JSON, SIM_NPZ, KEYFRAMES, PLAYBACK, FORCES, SUMMARY)


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
        default=math.pi / 2,
        metavar="RAD",
        help="goal orientation of the object, rad in W, any number within +-20 pi (default: pi/2)",
    )
    p.add_argument("--json", action="store_true", help="print summary.json instead of the text summary")
    add_config_options(p, formulation=True)
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

    goal = check_goal(args.goal, "--goal")
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
