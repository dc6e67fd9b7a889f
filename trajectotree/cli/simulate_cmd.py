"""`trajectotree simulate PLAN_DIR`: execute a saved plan in a full-dynamics Drake
simulation with the object-level grasp controller (--controller paper: eq. 20), optionally
in a world that differs from the plan's (--sim-mu, --sim-mass, --push); writes
PLAN_DIR/sim.json and sim.npz."""

from __future__ import annotations

import dataclasses
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

from trajectotree.cli import InputError
from trajectotree.cli.common import FIGURE_SUFFIXES, HTML_SUFFIXES, check_output_file, print_json
from trajectotree.config import Config, check_controller, config_from_dict, load_config


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="execute a saved plan with a controller in a Drake simulation",
                              description=__doc__)
    p.add_argument("plan_dir", metavar="PLAN_DIR", help="folder with plan.npz and plan.json (from `trajectotree plan`)")
    p.add_argument("--html", metavar="FILE", help="write a self-contained Meshcat playback of the run")
    p.add_argument("--gif", metavar="FILE", help="write a matplotlib GIF of the run (no WebGL needed)")
    p.add_argument("--forces", metavar="FILE.png",
                   help="plot each finger's simulated vs planned force on the box (.png, .pdf or .svg)")
    p.add_argument("--meshcat", action="store_true", help="watch live in Meshcat on localhost (runs in real time)")
    p.add_argument("--json", action="store_true", help="print sim.json to stdout")
    group = p.add_argument_group("execution settings (default: the plan's config; the scene must match the plan)")
    group.add_argument("--config", metavar="FILE.yaml", help="YAML file with the Config to execute with")
    group.add_argument("--box-size", nargs=2, type=float, metavar=("W", "H"), help="box width and height, m")
    group.add_argument("--mass", type=float, metavar="KG", help="box mass, kg")
    group.add_argument("--mu", type=float, metavar="MU", help="friction coefficient")
    group.add_argument("--controller", metavar="NAME",
                       help="grasp (object-level grasp control, the default) or paper (eq. 20)")
    group.add_argument("--kp", type=float, metavar="N/M", help="fingertip stiffness of eq. 20 (--controller paper)")
    group.add_argument("--kv", type=float, metavar="NS/M", help="fingertip damping of eq. 20 (--controller paper)")
    group.add_argument("--object-kp", type=float, metavar="1/S2", help="grasp controller: box pose gain, s^-2")
    group.add_argument("--object-kd", type=float, metavar="1/S", help="grasp controller: box velocity gain, s^-1")
    group.add_argument("--tip-kp", type=float, metavar="N/M", help="grasp controller: fingertip spring, N/m")
    group.add_argument("--tip-kd", type=float, metavar="NS/M", help="grasp controller: fingertip damping, N s/m")
    group.add_argument("--rate", type=float, metavar="HZ", help="grasp controller: control rate, Hz")
    world = p.add_argument_group("simulated world (differs from the plan's; the controller keeps the plan's values)")
    world.add_argument("--sim-mu", type=float, metavar="MU", help="friction coefficient of the simulated plant")
    world.add_argument("--sim-mass", type=float, metavar="KG", help="box mass of the simulated plant, kg")
    world.add_argument("--push", metavar="FX,FY@T",
                       help="push the box with force (FX, FY) N in W for sim.push_duration (0.2 s) from time T s")
    p.set_defaults(run=run)


def read_plan_dir(plan_dir: str) -> tuple[dict[str, np.ndarray], Config]:
    """The plan.npz arrays and the Config in plan.json; InputError when missing or corrupt."""
    from trajectotree.reference import check_plan_arrays
    folder = Path(plan_dir)
    if not folder.is_dir():
        raise InputError(f"PLAN_DIR {plan_dir!r} is not a directory")
    json_path, npz_path = folder / "plan.json", folder / "plan.npz"
    for path in (json_path, npz_path):
        if not path.is_file():
            raise InputError(f"{str(path)!r} is missing; PLAN_DIR must hold plan.json and plan.npz "
                             "from a successful `trajectotree plan`")
    try:
        data = json.loads(json_path.read_text())
        config = config_from_dict(data["config"])
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as e:
        raise InputError(f"{str(json_path)!r} is not a valid plan.json ({type(e).__name__}: {e})") from None
    try:
        with np.load(npz_path) as npz:
            arrays = {name: npz[name] for name in npz.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
        raise InputError(f"{str(npz_path)!r} is not a valid plan.npz: {e}") from None
    if not arrays:  # save_plan writes an empty plan.npz when planning produced nothing
        raise InputError(f"{str(npz_path)!r} holds no trajectory: planning produced none "
                         f"(plan.json status: {data.get('status')!r})")
    try:
        return check_plan_arrays(arrays), config
    except ValueError as e:
        raise InputError(f"{str(npz_path)!r} is not a valid plan.npz: {e}") from None


def execution_config(args, plan_config: Config) -> Config:
    """The plan's config (or --config) with the options on top; its scene must be the plan's."""
    config = load_config(args.config) if args.config else plan_config
    scene, gains = {}, {}
    if args.box_size is not None:
        scene["box_width"], scene["box_height"] = args.box_size
    if args.mass is not None:
        scene["box_mass"] = args.mass
    if args.mu is not None:
        scene["mu"] = args.mu
    if args.kp is not None:
        gains["kp"] = args.kp
    if args.kv is not None:
        gains["kv"] = args.kv
    for name in ("object_kp", "object_kd", "tip_kp", "tip_kd"):
        if getattr(args, name) is not None:
            gains[name] = getattr(args, name)
    if args.rate is not None:
        gains["rate_hz"] = args.rate
    if args.controller is not None:
        check_controller(args.controller, "--controller")
    sim = {} if args.controller is None else {"controller": args.controller}
    config = dataclasses.replace(config, scene=dataclasses.replace(config.scene, **scene),
                                 controller=dataclasses.replace(config.controller, **gains),
                                 sim=dataclasses.replace(config.sim, **sim))
    differ = [f"scene.{f.name} = {getattr(config.scene, f.name)!r} (the plan's: {getattr(plan_config.scene, f.name)!r})"
              for f in dataclasses.fields(config.scene)
              if getattr(config.scene, f.name) != getattr(plan_config.scene, f.name)]
    if differ:
        raise InputError("the given scene differs from the one the plan was made for: " + "; ".join(differ))
    return config


def plan_success_and_status(plan_dir: str) -> tuple[bool, str]:
    """plan.json's success and status (read_plan_dir has checked that it parses)."""
    data = json.loads((Path(plan_dir) / "plan.json").read_text())
    return bool(data.get("success")), str(data.get("status"))


def plan_segments(plan_dir: str, config: Config) -> list:
    """The segments of a TrajectoTree plan (report.segment_spans) for the forces figure;
    none for the baselines, whose contacts follow no contact sequence."""
    from trajectotree.report import segment_spans
    data = json.loads((Path(plan_dir) / "plan.json").read_text())
    if data.get("method") != "trajectotree":
        return []
    fingers = [node.get("switching_finger") for node in data.get("contact_sequence") or ()]
    return segment_spans(fingers, config.cito.knots_per_segment, config.cito.dt)


def save_sim_json_with_plan_status(result, plan_dir: str, plan_success: bool) -> dict:
    """Rewrites sim.json (save_sim writes the SimResult's keys) with `plan_success`, so a
    run of an unconverged plan cannot pass for the run of a converged one; returns it."""
    from trajectotree.io import SIM_JSON, write_bytes_atomic
    summary = dict(result.to_json(), plan_success=plan_success)
    write_bytes_atomic(Path(plan_dir) / SIM_JSON, (json.dumps(summary, indent=2) + "\n").encode())
    return summary


def world_conditions(args, config: Config) -> dict:
    """run_simulation's keyword arguments for --sim-mu, --sim-mass and --push, checked
    here so that bad values stop the command before anything is written."""
    from trajectotree.config import check_range
    from trajectotree.simulate import Conditions, parse_push
    if args.sim_mu is not None:
        check_range("--sim-mu", args.sim_mu, 0.0, 5.0, low_open=True)
    if args.sim_mass is not None:
        check_range("--sim-mass", args.sim_mass, 0.0, 100.0, low_open=True)
    push = None if args.push is None else parse_push(args.push, config.sim.push_duration)
    Conditions(mu=args.sim_mu, mass=args.sim_mass, push=push)   # raises ConfigError naming a bad value
    return {"sim_mu": args.sim_mu, "sim_mass": args.sim_mass, "push": push}


def run(args) -> int:
    from trajectotree.io import save_sim
    from trajectotree.playback import start_meshcat
    from trajectotree.reference import reference_from_arrays
    from trajectotree.report import figure_finger_forces, save_figure
    from trajectotree.scene import build_scene
    from trajectotree.simulate import run_simulation

    for option, path, suffixes in (("--html", args.html, HTML_SUFFIXES), ("--gif", args.gif, (".gif",)),
                                   ("--forces", args.forces, FIGURE_SUFFIXES)):
        if path:
            check_output_file(option, path, suffixes)
    arrays, plan_config = read_plan_dir(args.plan_dir)
    config = execution_config(args, plan_config)
    conditions = world_conditions(args, config)
    plan_status = plan_success_and_status(args.plan_dir)
    if not plan_status[0]:
        print(f"trajectotree simulate: warning: the plan in {args.plan_dir} did not converge (IPOPT status "
              f"{plan_status[1]!r}); executing it anyway, sim.json records plan_success: false", file=sys.stderr)
    meshcat = None
    if args.meshcat:
        meshcat = start_meshcat()
        print(f"Meshcat: {meshcat.web_url()}", file=sys.stderr if args.json else sys.stdout, flush=True)
    reference = reference_from_arrays(arrays, build_scene(config.scene))
    result = run_simulation(plan=reference, config=config, meshcat=meshcat, html_path=args.html, gif_path=args.gif,
                            **conditions)
    save_sim(result, args.plan_dir)
    summary = save_sim_json_with_plan_status(result, args.plan_dir, plan_status[0])
    if args.forces:
        save_figure(figure_finger_forces(result, plan_segments(args.plan_dir, plan_config)), args.forces)
    if args.json:
        print_json(summary)
    else:
        drop = f"DROPPED at {result.drop_time_s:.2f} s" if result.dropped else "held"
        print(f"simulated {summary['duration_s']:.2f} s in {result.sim_time_s:.1f} s: box {drop}; "
              f"MAE x {1e3 * result.mae_x:.1f} mm, y {1e3 * result.mae_y:.1f} mm, theta {result.mae_theta:.3f} rad")
        print(f"wrote {Path(args.plan_dir) / 'sim.json'}" + "".join(f", {p}" for p in (args.html, args.gif, args.forces) if p))
    if meshcat is not None and sys.stdin.isatty():
        input("Meshcat shows the recording; press Enter to exit. ")
    return 0
