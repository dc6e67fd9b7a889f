"""`trajectotree simulate PLAN_DIR` of a plan in space (plan.json `kind: space`, from `trajectotree plan --hand
fingerpro4`): the plan executed by the grasp controller in space (trajectotree.execution.space_run), open loop,
closed loop (--executor grasp-closed-loop, or --closed-loop) or closed loop replanning from the measured state
(--executor grasp-replan, or --replan: trajectotree.execution.space_replan), written as PLAN_DIR/sim.npz (t,
x (K, 7), x_plan (K, 7), q, f_W (K, F, 3), f_W_plan; closed loop also the plane's CLOSED_LOOP_ARRAYS) and
sim.json (dropped, the final orientation error in rad and position error in m, the executor; closed loop the final
estimates; replanning the replans with their outcomes); optionally watched as the plane's run is (--meshcat live,
--html the self-contained playback, --gif, --forces the forces figure), in the plan's world or another (--sim-mu,
--sim-mass, --push FX,FY,FZ@T: the controller keeps the plan's values)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from trajectotree.cli.common import check_output_dir, print_json
from trajectotree.cli.execution_options import chosen_executor, closed_loop_line, execution_config, world_conditions
from trajectotree.config import ConfigError, config_from_dict
from trajectotree.execution.space_plan import (
    check_arrays_fit_scene,
    read_space_plan,
    save_space_sim,
)
from trajectotree.io import PLAN_JSON, PLAN_NPZ, SIM_JSON, SIM_NPZ, reading
from trajectotree.scene.spatial import is_space_hand


def is_space_plan(plan_dir: str | Path) -> bool:
    """Whether PLAN_DIR's plan.json says it holds a plan in space (a missing or unreadable one: no, and the
    planar reader names what is wrong with it)."""
    try:
        data = json.loads((Path(plan_dir) / PLAN_JSON).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and data.get("kind") == "space"


def check_hand_fits_plan(args, space_plan: bool) -> None:
    """ConfigError naming --hand and the plan's kind when --hand names a hand of the other kind (a hand in space
    for a planar plan, or a planar hand for a plan in space)."""
    if args.hand is None or is_space_hand(args.hand) == space_plan:
        return
    given, plan = ("a planar hand", "a plan in space") if space_plan else ("a hand in space", "a planar plan")
    raise ConfigError(
        f"--hand {args.hand!r} is {given}, but PLAN_DIR {str(args.plan_dir)!r} holds {plan}: a plan executes with "
        "the hand it was made for (leave --hand out)"
    )


def simulate_space_into(args) -> int:
    """`simulate` of the plan in space in PLAN_DIR, whose lock the command holds."""
    from trajectotree.execution.space_control import SpaceReference
    from trajectotree.execution.space_run import SPACE_EXECUTORS, simulate_space
    from trajectotree.scene.spatial import build_space_scene

    check_hand_fits_plan(args, space_plan=True)
    check_output_dir("PLAN_DIR", args.plan_dir, (SIM_JSON, SIM_NPZ))
    data, arrays = read_space_plan(args.plan_dir)
    with reading(Path(args.plan_dir) / PLAN_JSON):
        plan_config = config_from_dict(data["config"])
    config = execution_config(args, plan_config)
    executor = chosen_executor(args, config)
    if executor not in SPACE_EXECUTORS:
        raise ConfigError(
            field="--executor",
            value=executor.value,
            problem="does not execute plans in space yet",
            choices=tuple(e.value for e in SPACE_EXECUTORS),
        )
    cube = data["object"]
    scene = build_space_scene(
        config.scene.hand, mu=config.scene.mu, gravity=config.scene.gravity, size=cube["size"], mass=cube["mass"]
    )
    check_arrays_fit_scene(Path(args.plan_dir) / PLAN_NPZ, arrays, scene)
    conditions = space_world(args, config, float(arrays["t"][-1] - arrays["t"][0]))
    plan_success = bool(data.get("success"))
    if not plan_success:
        print(
            f"trajectotree simulate: warning: the plan in {args.plan_dir} did not succeed ({data.get('status')!r}); "
            "executing it anyway, sim.json records plan_success: false",
            file=sys.stderr,
        )
    meshcat = None
    if args.meshcat:
        from trajectotree.execution.meshcat_scene import start_meshcat

        meshcat = start_meshcat()
        print(f"Meshcat: {meshcat.web_url()}", file=sys.stderr if args.json else sys.stdout, flush=True)
    reference = SpaceReference.from_arrays(arrays)
    result = simulate_space(
        reference,
        config,
        scene,
        executor=executor,
        conditions=conditions,
        meshcat=meshcat,
        html_path=args.html,
        goal=data.get("goal_quaternion"),
    )
    summary = save_space_sim(result, args.plan_dir, plan_success)
    write_space_pictures(args, result, reference, scene, data.get("goal_quaternion"))
    if args.json:
        print_json(summary)
    else:
        from trajectotree.figures.run import world_text

        outcome = f"DROPPED at {result.drop_time_s:.2f} s" if result.dropped else "held"
        world = world_text(result.conditions)
        outcome += f" ({world})" if world else ""
        print(
            f"simulated {summary['duration_s']:.2f} s in {result.sim_time_s:.1f} s ({executor.value}): {outcome}; "
            f"final orientation error {np.degrees(summary['final_orientation_error_rad']):.2f} deg, position error "
            f"{1e3 * summary['final_position_error_m']:.2f} mm (largest on the way "
            f"{np.degrees(summary['max_orientation_error_rad']):.2f} deg, "
            f"{1e3 * summary['max_position_error_m']:.2f} mm)"
        )
        if result.closed_loop is not None:
            print(closed_loop_line(summary["closed_loop"], config.scene.mu, scene.object.mass))
        for line in replan_lines(result.replans):
            print(line)
        print(
            f"wrote {Path(args.plan_dir) / SIM_JSON}, {Path(args.plan_dir) / SIM_NPZ}"
            + "".join(f", {p}" for p in (args.html, args.gif, args.forces) if p)
        )
    if meshcat is not None and sys.stdin.isatty():
        input("Meshcat shows the recording; press Enter to exit. ")
    return 0


def space_world(args, config, plan_duration_s: float):
    """The simulated world of --sim-mu, --sim-mass and --push FX,FY,FZ@T (execution.world's Conditions), checked as
    the plane's (execution_options.world_conditions) before anything is written."""
    from trajectotree.execution.world import Conditions

    world = world_conditions(args, config, plan_duration_s, components=3)
    return Conditions(mu=world["sim_mu"], mass=world["sim_mass"], push=world["push"])


def write_space_pictures(args, result, reference, scene, goal) -> None:
    """--gif (the run on 3D axes) and --forces (each finger's simulated vs planned force on the cube, titled with
    the plan's `goal` quaternion) of a run in space, its arrows at the plan's scale."""
    if args.gif:
        write_space_gif(result, reference, scene, args.gif)
    if args.forces:
        from trajectotree.figures.run import figure_finger_forces, save_figure

        save_figure(figure_finger_forces(result, goal=goal, noun="cube"), args.forces)


def write_space_gif(result, reference, scene, path) -> None:
    """The run in space as a GIF (execution.gif on 3D axes): the cube as simulated, the planned cube dashed, the
    simulated forces at the plan's arrow scale."""
    from trajectotree.execution.gif import write_gif
    from trajectotree.execution.space_run import space_arrow_scale
    from trajectotree.figures.legend import controller_text

    write_gif(
        scene,
        result.t,
        result.x,
        result.q,
        path,
        planned_poses=result.x_plan,
        forces=result.f_W,
        newtons_per_cm=space_arrow_scale(reference),
        title=f"simulated run, {controller_text(result.controller)}",
    )


def replan_lines(replans) -> list[str]:
    """A line per replan (results.ReplanEvent): when, why, the estimates it planned with, its outcome and times."""
    return [
        f"replan at {e.time_s:.2f} s ({e.reason.value}; friction {e.mu:.3f}, mass {1e3 * e.mass:.1f} g): "
        f"{e.outcome.value}, after {e.latency_s:.2f} s (search {e.search_s:.2f} s)"
        + ("" if e.planned else f" ({e.status})")
        for e in replans
    ]
