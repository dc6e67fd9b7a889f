"""`trajectotree simulate PLAN_DIR`: execute a saved plan in a full-dynamics Drake
simulation with the object-level grasp controller (--controller paper: eq. 20), optionally
with its closed loop (--closed-loop) and in a world that differs from the plan's (--sim-mu,
--sim-mass, --push); writes PLAN_DIR/sim.json and sim.npz."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from trajectotree.cli.common import (
    FIGURE_SUFFIXES,
    HTML_SUFFIXES,
    add_scene_options,
    check_executable_hand,
    check_output_dir,
    check_output_file,
    print_json,
)
from trajectotree.cli.execution_options import (
    chosen_executor,
    closed_loop_line,
    execution_config,
    named_executor,
    world_conditions,
)
from trajectotree.config import (
    MAX_BOX_MASS,
    MAX_KP,
    MAX_KV,
    MAX_MU,
    MAX_OBJECT_KD,
    MAX_OBJECT_KP,
    MAX_TIP_KD,
    MAX_TIP_KP,
    MIN_BOX_MASS,
    Config,
    ConfigError,
    clipped_repr,
    interval,
)
from trajectotree.config.executor import EXECUTORS
from trajectotree.io import (
    SIM_JSON,
    SIM_NPZ,
    PlanFiles,
    folder_lock,
    read_plan_files,
    reading,
    write_json_atomic,
)
from trajectotree.results import RunOutcome, outcome_text


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="execute a saved plan with a controller in a Drake simulation", description=__doc__
    )
    p.add_argument(
        "plan_dir",
        metavar="PLAN_DIR",
        help="folder with plan.npz and plan.json (from `trajectotree plan`); the command holds "
        "PLAN_DIR/.lock while it runs, so no `plan` replaces the plan meanwhile",
    )
    p.add_argument("--html", metavar="FILE", help="write a self-contained Meshcat playback of the run")
    p.add_argument("--gif", metavar="FILE", help="write a matplotlib GIF of the run (no WebGL needed)")
    p.add_argument(
        "--forces",
        metavar="FILE.png",
        help="plot each finger's simulated vs planned force on the object (.png, .pdf or .svg)",
    )
    p.add_argument("--meshcat", action="store_true", help="watch live in Meshcat on localhost (runs in real time)")
    p.add_argument("--json", action="store_true", help="print sim.json to stdout")
    group = p.add_argument_group("execution settings (default: the plan's config; the scene must match the plan)")
    add_scene_options(group, config_help="YAML file with the Config to execute with")
    group.add_argument(
        "--executor",
        metavar="NAME",
        help=f"how the plan is executed, one of {', '.join(EXECUTORS)} (grasp: the object-level grasp controller "
        "open loop; grasp-closed-loop: with the closed loop, as --closed-loop; grasp-replan: replanning too, as "
        "--replan; paper: eq. 20; none: the motors off); default: --controller's, open loop",
    )
    group.add_argument(
        "--controller", metavar="NAME", help="grasp (object-level grasp control, the default) or paper (eq. 20)"
    )
    for option, metavar, what, high in (
        ("--kp", "N/M", "fingertip stiffness of eq. 20 (--controller paper), N/m", MAX_KP),
        ("--kv", "NS/M", "fingertip damping of eq. 20 (--controller paper), N s/m", MAX_KV),
        ("--object-kp", "1/S2", "grasp controller: object pose gain, s^-2", MAX_OBJECT_KP),
        ("--object-kd", "1/S", "grasp controller: object velocity gain, s^-1", MAX_OBJECT_KD),
        ("--tip-kp", "N/M", "grasp controller: fingertip spring, N/m", MAX_TIP_KP),
        ("--tip-kd", "NS/M", "grasp controller: fingertip damping, N s/m", MAX_TIP_KD),
    ):
        group.add_argument(option, type=float, metavar=metavar, help=f"{what}, in {interval(0.0, high)}")
    group.add_argument("--rate", type=float, metavar="HZ", help="grasp controller: control rate, Hz, in [10, 10000]")
    group.add_argument(
        "--closed-loop",
        action="store_true",
        help="grasp controller: watch the contacts (slip), estimate the friction and the box mass for the "
        "grasp forces and squeeze harder against pushes (sim.npz then holds what the loop saw)",
    )
    group.add_argument(
        "--replan",
        action="store_true",
        help="closed loop, and plan again from the measured state at a node when the friction or mass "
        "estimate or the tracking error says the plan no longer holds (controller.replan); the new plan takes "
        "effect once its measured compute time has passed in simulated time",
    )
    group.add_argument(
        "--friction-floor",
        type=float,
        metavar="MU",
        help="closed loop: the friction estimate never goes below this, in (0, 1] (default 0.2)",
    )
    world = p.add_argument_group("simulated world (differs from the plan's; the controller keeps the plan's values)")
    world.add_argument(
        "--sim-mu",
        type=float,
        metavar="MU",
        help=f"friction coefficient of the simulated plant, in {interval(0.0, MAX_MU, low_open=True)}",
    )
    world.add_argument(
        "--sim-mass",
        type=float,
        metavar="KG",
        help=f"object mass of the simulated plant, kg, in {interval(MIN_BOX_MASS, MAX_BOX_MASS)}",
    )
    world.add_argument(
        "--push",
        metavar="FX,FY@T",
        help="push the object with force (FX, FY) N in W for sim.push_duration (0.2 s) from time T s; a plan in "
        "space takes FX,FY,FZ@T",
    )
    p.set_defaults(run=run)


def trajectory_arrays(files: PlanFiles) -> dict[str, np.ndarray]:
    """The plan.npz arrays of a plan folder as checked floats (reference.check_plan_arrays);
    ConfigError naming plan.npz when it holds none (planning produced none) or bad ones."""
    from trajectotree.execution.reference import check_plan_arrays

    if not files.arrays:  # save_plan writes an empty plan.npz when planning produced nothing
        raise ConfigError(
            f"{str(files.npz_path)!r} holds no trajectory: planning produced none "
            f"(plan.json status: {clipped_repr(files.data.get('status'))})"
        )
    with reading(files.npz_path):
        return check_plan_arrays(files.arrays)


# m (and rad), how far a plan's arrays may stray from the scene plan.json records: they meet it to
# rounding (p_W_C is placed on the object's boundary, x[0] is fixed to scene.initial_pose), while a
# plan.json beside another plan's plan.npz misses by millimetres (a 0.15 m box beside the 0.20 m
# box's arrays: contact points 25 mm off its boundary).
FIT_TOL = 1e-4


def check_arrays_fit_plan(files: PlanFiles, arrays: dict[str, np.ndarray]) -> None:
    """ConfigError naming the mismatch when plan.npz's arrays do not belong to the plan plan.json
    describes (the two files of different plans side by side): every contact point p_W_C on the
    boundary of plan.json's object at the planned pose, x[0] at its scene.initial_pose, and for a
    TrajectoTree plan its knots cito.dt apart (io.read_plan_files has checked the arrays' digest
    plan.json records and their knots per transition of its contact sequence)."""
    from trajectotree.geometry import poses_world_to_box
    from trajectotree.scene.plant import describe_object

    config, x = files.config, arrays["x"]
    where = f"{str(files.npz_path)!r} does not belong to the plan {str(files.json_path)!r} describes"
    off = np.abs(config.scene.shape.signed_distances(poses_world_to_box(x, arrays["p_W_C"])))
    k, i = np.unravel_index(int(np.argmax(off)), off.shape)
    if off[k, i] > FIT_TOL:
        raise ConfigError(
            f"{where}: its contact points lie up to {1e3 * off[k, i]:.2f} mm off the {describe_object(config.scene)} "
            f"plan.json records (finger {i} at knot {k}; a plan's own lie on its object within "
            f"{1e3 * FIT_TOL:g} mm): put the plan.json and plan.npz of one plan together, or plan again"
        )
    start = np.abs(x[0] - np.asarray(config.scene.initial_pose, dtype=float)).max()
    if start > FIT_TOL:
        raise ConfigError(
            f"{where}: it starts at pose {x[0].round(4).tolist()}, plan.json's scene.initial_pose is "
            f"{list(config.scene.initial_pose)}"
        )
    nodes = files.data.get("contact_sequence") or ()
    if files.data.get("method") != "trajectotree" or len(nodes) < 2:
        return
    steps = np.diff(arrays["t"])
    if np.abs(steps - config.cito.dt).max() > 1e-9:
        raise ConfigError(
            f"{where}: its knots are {steps.min():g}-{steps.max():g} s apart, plan.json's cito.dt is "
            f"{config.cito.dt:g} s"
        )


def read_plan_dir(plan_dir: str) -> tuple[dict[str, np.ndarray], Config]:
    """The plan.npz arrays and the Config in plan.json; ConfigError when missing or corrupt."""
    files = read_plan_files(plan_dir, "PLAN_DIR")
    arrays = trajectory_arrays(files)
    check_arrays_fit_plan(files, arrays)
    return arrays, files.config


def plan_segments(files: PlanFiles) -> list:
    """The segments of a TrajectoTree plan (figures.segment_spans) for the forces figure;
    none for the baselines, whose contacts follow no contact sequence."""
    from trajectotree.figures.run import segment_spans

    if files.data.get("method") != "trajectotree":
        return []
    fingers = [node.get("switching_finger") for node in files.data.get("contact_sequence") or ()]
    return segment_spans(fingers, files.config.cito.knots_per_segment, files.config.cito.dt)


def save_sim_json_with_plan_status(result, plan_dir: str, plan_success: bool) -> dict:
    """Rewrites sim.json (save_sim writes the SimResult's keys) with `plan_success`, so a
    run of an unconverged plan cannot pass for the run of a converged one; returns it."""
    summary = dict(result.to_json(), plan_success=plan_success)
    write_json_atomic(Path(plan_dir) / SIM_JSON, summary)
    return summary


def final_error_line(summary: dict) -> str:
    """The error at the end of the run, and at the drop when there was one (sim.json's final_error,
    error_at_drop): a box caught again after the drop rule fired may end on the plan."""
    x, y, theta = summary["final_error"]
    line = f"final error x {1e3 * x:.1f} mm, y {1e3 * y:.1f} mm, theta {theta:.3f} rad at the end of the run"
    if summary.get("error_at_drop") is not None:
        x, y, theta = summary["error_at_drop"]
        line += f"; at the drop: x {1e3 * x:.1f} mm, y {1e3 * y:.1f} mm, theta {theta:.3f} rad"
    return line


def run(args) -> int:
    named_executor(args)  # before the lock and any file is read
    for option, path, suffixes in (
        ("--html", args.html, HTML_SUFFIXES),
        ("--gif", args.gif, (".gif",)),
        ("--forces", args.forces, FIGURE_SUFFIXES),
    ):
        if path:
            check_output_file(option, path, suffixes)
    # no `plan` replaces the plan, nor another `simulate` its run, while this one reads and writes them
    with folder_lock(args.plan_dir, "PLAN_DIR", "trajectotree simulate", create=False):
        return simulate_into(args)


def simulate_into(args) -> int:
    """Executes the plan in PLAN_DIR, whose lock this command holds, and writes the run there."""
    from trajectotree.cli.space_simulate import check_hand_fits_plan, is_space_plan, simulate_space_into

    if is_space_plan(args.plan_dir):  # its own reader and Diagram
        return simulate_space_into(args)
    check_hand_fits_plan(args, space_plan=False)
    from trajectotree.execution.meshcat_scene import start_meshcat
    from trajectotree.execution.playback_page import object_noun
    from trajectotree.execution.reference import reference_from_arrays
    from trajectotree.execution.run import run_simulation
    from trajectotree.figures.run import figure_finger_forces, save_figure
    from trajectotree.io import save_sim
    from trajectotree.scene.plant import build_scene

    files = read_plan_files(args.plan_dir, "PLAN_DIR")
    if files.unverified:
        print(f"trajectotree simulate: warning: {files.unverified}", file=sys.stderr)
    check_output_dir("PLAN_DIR", args.plan_dir, (SIM_JSON, SIM_NPZ))  # the run is saved there: before it runs
    arrays = trajectory_arrays(files)
    check_arrays_fit_plan(files, arrays)
    config = execution_config(args, files.config)
    scene = build_scene(config.scene)
    check_executable_hand(scene, "the simulation")
    with reading(files.npz_path):  # the plan's finger count is its hand's
        from trajectotree.execution.reference import check_plan_arrays

        check_plan_arrays(arrays, scene.num_fingers)
    conditions = world_conditions(args, config, float(arrays["t"][-1] - arrays["t"][0]))
    executor = chosen_executor(args, config)
    plan_success = bool(files.data.get("success"))
    if not plan_success:
        print(
            f"trajectotree simulate: warning: the plan in {args.plan_dir} did not converge (IPOPT status "
            f"{clipped_repr(str(files.data.get('status')))}); executing it anyway, sim.json records "
            "plan_success: false",
            file=sys.stderr,
        )
    meshcat = None
    if args.meshcat:
        meshcat = start_meshcat()
        print(f"Meshcat: {meshcat.web_url()}", file=sys.stderr if args.json else sys.stdout, flush=True)
    if executor.replans:  # the planner needs the plan itself (its goal and config), not only its arrays
        from trajectotree.io import load_plan

        plan = load_plan(args.plan_dir)
    else:
        plan = reference_from_arrays(arrays, build_scene(config.scene))
    result = run_simulation(
        plan=plan,
        config=config,
        meshcat=meshcat,
        html_path=args.html,
        gif_path=args.gif,
        executor=executor,
        **conditions,
    )
    save_sim(result, args.plan_dir)
    summary = save_sim_json_with_plan_status(result, args.plan_dir, plan_success)
    if args.forces:
        save_figure(figure_finger_forces(result, plan_segments(files), goal=files.data.get("goal")), args.forces)
    if args.json:
        print_json(summary)
    else:
        held = {RunOutcome.DROPPED: "drop", RunOutcome.DIVERGED: "divergence"}.get(result.outcome)
        print(
            f"simulated {summary['duration_s']:.2f} s in {result.sim_time_s:.1f} s: "
            f"{outcome_text(summary, object_noun(config.scene))}; "
            f"MAE x {1e3 * result.mae_x:.1f} mm, y {1e3 * result.mae_y:.1f} mm, theta {result.mae_theta:.3f} rad"
            + (f" (errors held at their values at the {held} from then on)" if held else "")
        )
        print(final_error_line(summary))
        loop = summary["closed_loop"]
        if loop is not None:
            print(closed_loop_line(loop, config.scene.mu, config.scene.box_mass))
        for e in result.replans:
            print(
                f"replan at {e.time_s:.2f} s ({e.reason.value}; friction {e.mu:.3f}, mass {1e3 * e.mass:.1f} g): "
                f"{e.outcome.value}, after {e.latency_s:.3f} s" + ("" if e.planned else f" ({e.status})")
            )
        print(
            f"wrote {Path(args.plan_dir) / 'sim.json'}"
            + "".join(f", {p}" for p in (args.html, args.gif, args.forces) if p)
        )
    if meshcat is not None and sys.stdin.isatty():
        input("Meshcat shows the recording; press Enter to exit. ")
    return 0
