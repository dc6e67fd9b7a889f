"""`trajectotree simulate PLAN_DIR` of a plan in space (plan.json `kind: space`, from `trajectotree plan --hand
fingerpro4`): the plan executed by the grasp controller in space (trajectotree.execution.space_run), open loop or
closed loop (--executor grasp-closed-loop, or --closed-loop), written as PLAN_DIR/sim.npz (t, x (K, 7), x_plan
(K, 7), q, f_W (K, F, 3), f_W_plan; closed loop also the plane's CLOSED_LOOP_ARRAYS) and sim.json (dropped, the
final orientation error in rad and position error in m, the executor; closed loop the final estimates); optionally
watched as the plane's run is (--meshcat live, --html the self-contained playback, --gif, --forces the forces
figure). What space does not have yet (replanning, the other world) is refused before anything is read or
written."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import numpy as np

from trajectotree.cli.common import check_output_dir, print_json
from trajectotree.cli.simulate_cmd import chosen_executor, closed_loop_line, execution_config
from trajectotree.config import ConfigError, config_from_dict
from trajectotree.io import SIM_JSON, SIM_NPZ, reading, require_files, write_bytes_atomic, write_json_atomic
from trajectotree.scene.spatial import is_space_hand

PLAN_JSON, PLAN_NPZ = "plan.json", "plan.npz"
# m, how far a plan's contact points may lie off the surface of the cube plan.json names (a plan's own lie on it
# to rounding; the arrays of another cube's plan miss it by millimetres), as the plane's simulate_cmd.FIT_TOL
FIT_TOL = 1e-4
# The options of `simulate` that a plan in space does not take yet, by their argparse names.
NOT_YET = {
    "replan": "--replan",
    "sim_mu": "--sim-mu",
    "sim_mass": "--sim-mass",
    "push": "--push",
}


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


def refuse_not_yet(args) -> None:
    """ConfigError naming the first option a plan in space does not take yet."""
    given = [option for name, option in NOT_YET.items() if getattr(args, name, None) not in (None, False)]
    if given:
        raise ConfigError(
            f"{given[0]} does not work with a plan in space yet (PLAN_DIR {str(args.plan_dir)!r}): execution by "
            "the grasp controller, open or closed loop, in the plan's world only, so far"
        )


def read_space_plan(plan_dir: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """plan.json's data and plan.npz's arrays (their shapes checked against each other: planning.physics.
    check_space_arrays); ConfigError naming the file and what is wrong."""
    from trajectotree.planning.physics import check_space_arrays
    from trajectotree.results import SPACE_TRAJECTORY_ARRAYS

    folder = Path(plan_dir)
    json_path, npz_path = folder / PLAN_JSON, folder / PLAN_NPZ
    require_files((json_path, npz_path), "a plan folder holds plan.json and plan.npz (written by `trajectotree plan`)")
    with reading(json_path):
        data = json.loads(json_path.read_text())
        if not isinstance(data.get("object"), dict) or not isinstance(data.get("config"), dict):
            raise ValueError("a plan in space's plan.json names its object and its config")
    with reading(npz_path), np.load(npz_path) as npz:
        arrays = {name: np.array(npz[name]) for name in npz.files}
    missing = [name for name in SPACE_TRAJECTORY_ARRAYS if name not in arrays]
    if missing:
        raise ConfigError(f"{str(npz_path)!r} lacks the array(s) {', '.join(missing)} of a plan in space")
    try:
        return data, check_space_arrays(arrays)
    except ValueError as e:
        raise ConfigError(f"{str(npz_path)!r}: {e}") from None


def check_arrays_fit_scene(npz_path: Path, arrays: dict[str, np.ndarray], scene) -> None:
    """ConfigError naming plan.npz and the mismatch when its arrays do not belong to the scene plan.json names:
    its fingers and joints the hand's, every contact point on the cube's surface at the planned pose."""
    from trajectotree.geometry import box_signed_distances, quaternion_matrices

    F, joints = scene.num_fingers, scene.tau_max.size
    if arrays["f_W"].shape[1] != F or arrays["q"].shape[1] != joints:
        raise ConfigError(
            f"{str(npz_path)!r} has {arrays['f_W'].shape[1]} fingers and {arrays['q'].shape[1]} joints; hand "
            f"{scene.hand_file.source!r} has {F} and {joints}: put the plan.json and plan.npz of one plan together"
        )
    x = arrays["x"]
    p_BC = np.einsum("kji,kfj->kfi", quaternion_matrices(x[:, :4]), arrays["p_W_C"] - x[:, None, 4:])
    off = np.abs(box_signed_distances(scene.object.half, p_BC))
    k, i = np.unravel_index(int(np.argmax(off)), off.shape)
    if off[k, i] > FIT_TOL:
        raise ConfigError(
            f"{str(npz_path)!r}: its contact points lie up to {1e3 * off[k, i]:.2f} mm off the "
            f"{' x '.join(f'{1e3 * s:g}' for s in scene.object.size)} mm cube plan.json names (finger {i} at knot "
            f"{k}; a plan's own lie on its cube within {1e3 * FIT_TOL:g} mm): put the plan.json and plan.npz of one "
            "plan together, or plan again"
        )


def save_space_sim(result, plan_dir: str | Path, plan_success: bool) -> dict:
    """PLAN_DIR/sim.npz (the result's arrays, a closed-loop run's estimates too) and sim.json (its summary, with
    `plan_success`), each written atomically; returns the summary."""
    buffer = io.BytesIO()
    arrays = {name: getattr(result, name) for name in result.ARRAYS}
    np.savez(buffer, **arrays, **({} if result.closed_loop is None else result.closed_loop.arrays()))
    write_bytes_atomic(Path(plan_dir) / SIM_NPZ, buffer.getvalue())
    summary = dict(result.to_json(), plan_success=plan_success)
    write_json_atomic(Path(plan_dir) / SIM_JSON, summary)
    return summary


def simulate_space_into(args) -> int:
    """`simulate` of the plan in space in PLAN_DIR, whose lock the command holds."""
    from trajectotree.execution.space_control import SpaceReference
    from trajectotree.execution.space_run import SPACE_EXECUTORS, simulate_space
    from trajectotree.scene.spatial import build_space_scene

    check_hand_fits_plan(args, space_plan=True)
    refuse_not_yet(args)
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
    result = simulate_space(reference, config, scene, executor=executor, meshcat=meshcat, html_path=args.html)
    summary = save_space_sim(result, args.plan_dir, plan_success)
    write_space_pictures(args, result, reference, scene, data.get("goal_quaternion"))
    if args.json:
        print_json(summary)
    else:
        outcome = f"DROPPED at {result.drop_time_s:.2f} s" if result.dropped else "held"
        print(
            f"simulated {summary['duration_s']:.2f} s in {result.sim_time_s:.1f} s ({executor.value}): {outcome}; "
            f"final orientation error {np.degrees(summary['final_orientation_error_rad']):.2f} deg, position error "
            f"{1e3 * summary['final_position_error_m']:.2f} mm (largest on the way "
            f"{np.degrees(summary['max_orientation_error_rad']):.2f} deg, "
            f"{1e3 * summary['max_position_error_m']:.2f} mm)"
        )
        if result.closed_loop is not None:
            print(closed_loop_line(summary["closed_loop"], config.scene.mu, scene.object.mass))
        print(
            f"wrote {Path(args.plan_dir) / SIM_JSON}, {Path(args.plan_dir) / SIM_NPZ}"
            + "".join(f", {p}" for p in (args.html, args.gif, args.forces) if p)
        )
    if meshcat is not None and sys.stdin.isatty():
        input("Meshcat shows the recording; press Enter to exit. ")
    return 0


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
