"""`trajectotree scene`: build the plant from the models and a config, print a summary."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trajectotree.cli.common import FIGURE_SUFFIXES, add_config_options, check_output_file, config_from_args, print_json
from trajectotree.scene.plant import describe_object

FIGURE_GOAL = math.pi / 2  # rad, the goal whose plan's initial grasp `--figure` draws: the demo's quarter turn


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "scene",
        help="build the hand and object plant, summarize it, tell whether the hand can grasp the object",
        description=__doc__,
    )
    add_config_options(p, segments=False, space=True)
    p.add_argument(
        "--figure",
        metavar="FILE.png",
        help="draw the model (hand at the initial grasp of a plan to a quarter turn, object, "
        "reach circles, each finger's reachable contacts); .png, .pdf or .svg",
    )
    p.add_argument(
        "--rotations",
        action="store_true",
        help="also run the contact search for goal rotations every 5 deg outwards from the start, up to "
        "180 deg each way, and report how far it finds contact sequences (seconds to a minute)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(run=run)


def describe(scene) -> dict:
    """The object as the plant has it: outline, area, mass and inertia about z (from the body)."""
    c, shape = scene.config, scene.config.shape
    body = scene.plant.GetBodyByName("box", scene.box)
    inertia = body.default_spatial_inertia().CalcRotationalInertia().CopyToFullMatrix3()
    out = {
        "kind": "box" if shape.is_box else "polygon",
        "name": describe_object(c),
        "vertices_m": shape.vertices.round(6).tolist(),
        "area_m2": shape.area,
        "perimeter_m": shape.perimeter,
        "depth_m": c.box_depth,
        "mass_kg": body.default_mass(),
        "inertia_zz_kg_m2": float(inertia[2, 2]),
        "mu": c.mu,
    }
    if shape.is_box:
        out["size_m"] = [2 * shape.box_half[0], 2 * shape.box_half[1]]
    return out


def summarize(scene, reach: dict | None = None) -> dict:
    out = {"object": describe(scene)}
    if reach is not None:
        out["reach"] = reach
    return out | {
        "gravity_W": scene.plant.gravity_field().gravity_vector().tolist(),
        "num_positions": scene.plant.num_positions(),
        "num_actuators": scene.plant.num_actuators(),
        "tip_radius_m": scene.tip_radius,
        "fingers": [
            {
                "base_W": f.p_W_base.round(6).tolist(),
                "link_lengths_m": [round(f.l1, 6), round(f.l2, 6)],
                "q_lower": f.q_lower.tolist(),
                "q_upper": f.q_upper.tolist(),
                "tau_max": f.tau_max.tolist(),
            }
            for f in scene.fingers
        ],
    }


@dataclass(frozen=True)
class ObjectReach:
    """Whether the hand can grasp the object at its initial pose."""

    contacts: list  # per finger, arclengths (m) of its reachable corner-free grid contacts
    #                           (initial_grasp.grid_contacts: what the initial grasps are built from)
    grasps: object  # initial_grasp.GraspCandidates
    # (2F,) rad, the joint angles (Drake IK, as the search's) of the initial grasp a plan for FIGURE_GOAL starts
    # from (search.tree.choose_initial_grasp; None: no plan root for it)
    q_start: np.ndarray | None
    start: tuple | None  # m, that grasp's contacts' arclengths (None: none)
    payload: object  # search.payload.Payload: the heaviest object they carry (None without a grasp)
    workspace: object  # search.workspace.Workspace: where the hand can move the object (None without a grasp)

    def to_json(self, search) -> dict:
        g = self.grasps
        best = g.candidates[0] if g.candidates else None
        return {
            "graspable": best is not None,
            "grid_step_m": search.initial_grid_step,
            "contacts_per_finger": [len(s) for s in self.contacts],
            "mu_plan": g.mu_plan,
            "initial_grasps": len(g.candidates),
            "best_grasp_arclengths_m": None if best is None else list(best.arclengths),
            "best_grasp_worst_stance_mu": None if best is None else best.worst_stance_mu,
            "start_grasp_goal_rad": FIGURE_GOAL,
            "start_grasp_arclengths_m": None if self.start is None else list(self.start),
            "reason": "" if g.refusal is None else str(g.refusal),
            "refusal": None if g.refusal is None else g.refusal.to_json(),
            "payload": None if self.payload is None else self.payload.to_json(),
            "workspace": None if self.workspace is None else self.workspace.to_json(),
        }


def object_reach(scene, search) -> ObjectReach:
    from trajectotree.search.initial_grasp import GraspTables, grid_contacts
    from trajectotree.search.payload import payload
    from trajectotree.search.reach import Reachability
    from trajectotree.search.tree import choose_initial_grasp
    from trajectotree.search.workspace import Graspability, workspace

    reach, tables = Reachability(scene), GraspTables()
    grasps = tables.get(scene, search, reach)
    start, q = None, None
    if grasps.candidates:
        # the grasp the search roots a plan at, not the best-ranked candidate: that one may fail the
        # search's checks before its tree (the seed-0 box's did: two fingers out of reach at node 1)
        start, _ = choose_initial_grasp(scene, FIGURE_GOAL, search, tables)
    if start is not None:
        pose = np.asarray(scene.config.initial_pose, dtype=float)
        q = np.concatenate([reach.solve(pose, i, s).q for i, s in enumerate(start)])
    contacts = grid_contacts(scene, search.initial_grid_step, reach)
    limits = payload(scene, search, grasps) if grasps.candidates else None
    reachable = workspace(scene, search, Graspability(scene, search, reach)) if grasps.candidates else None
    return ObjectReach(contacts=contacts, grasps=grasps, q_start=q, start=start, payload=limits, workspace=reachable)


def reach_line(reach: dict) -> str:
    counts = reach["contacts_per_finger"]
    line = f"reach at the initial pose: {counts} corner-free contacts (every {reach['grid_step_m']:g} m) per finger; "
    if reach["graspable"]:
        return line + (
            f"{reach['initial_grasps']} initial grasps, the best needs mu "
            f"{reach['best_grasp_worst_stance_mu']:.3g} of mu_plan {reach['mu_plan']:.3g}"
        )
    return line + f"the hand CANNOT grasp the object: {reach['reason']}"


def workspace_line(reach: dict) -> str:
    """Where goal poses may take the object (search.workspace)."""
    w = reach["workspace"]

    def region(r: dict) -> str:
        if not r["points"]:
            return "nowhere"
        x, y = r["x_range_m"], r["y_range_m"]
        return (
            f"within {r['radius_m']:.3g} m ({r['points']} grid points, x {x[0]:+.2f}..{x[1]:+.2f}, "
            f"y {y[0]:+.2f}..{y[1]:+.2f} m)"
        )

    return (
        f"workspace: translations of the start (on a {w['grid_step_m']:g} m grid) where the hand has an initial "
        f"grasp: at every orientation (every {360 / w['orientations']:g} deg of a turn) "
        f"{region(w['every_orientation'])}; at the start orientation {region(w['start_orientation'])}; "
        "a goal pose must keep every node of its path graspable (--goal-pose)"
    )


def rotations_line(r: dict) -> str:
    """How far the contact search turns the object in place (search.workspace.rotation_range)."""
    step, (ccw, cw) = math.degrees(r["step_rad"]), r["first_refused_rad"]

    def deg(v: float) -> str:
        return f"{math.degrees(v):+.0f} deg"

    misses = [deg(v) for v in (cw, ccw) if v is not None]
    return (
        f"rotations: the contact search finds a sequence for every goal every {step:g} deg in "
        f"[{deg(-r['cw_rad'])}, {deg(r['ccw_rad'])}] ([{-r['cw_rad']:+.4f}, {r['ccw_rad']:+.4f}] rad; "
        f"tested up to {math.degrees(r['limit_rad']):g} deg each way); "
        + (f"none at {' and '.join(misses)}" if misses else "every tested goal planned")
    )


def payload_line(reach: dict, mass: float) -> str:
    """What the hand can carry (search.payload) against the object's mass."""
    from trajectotree.planning.request import floor_digits

    p = reach["payload"]
    hold, switch = floor_digits(p["hold_kg"]), floor_digits(p["switch_kg"])
    line = (
        f"payload: the initial grasps hold at most {hold:g} kg at rest, {switch:g} kg while a finger lets go "
        f"(joints within {p['tau_max_Nm']:g} N m"
        + (
            f", stance force within search.max_stance_force {p['max_stance_force_N']:g} N"
            if p["max_stance_force_N"]
            else ""
        )
        + "); "
    )
    if mass > p["hold_kg"]:
        return line + f"the hand CANNOT hold the object's {mass:g} kg (planning refuses it)"
    if mass > p["switch_kg"]:
        return line + f"the object's {mass:g} kg allows only plans that switch no finger"
    return line + f"the object weighs {mass:g} kg"


def draw_model(scene, path: str, reach: ObjectReach | None = None) -> None:
    """The hand (at the initial grasp a quarter turn's plan starts from, if any) and the object, each finger's reachable
    contacts (figures.figure_model), written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.figures.run import figure_model, save_figure

    if reach is None:
        fig = figure_model(scene)
    else:
        counts = [len(s) for s in reach.contacts]
        note = f"dots: reachable contacts {tuple(counts)}; " + (
            f"hand: the initial grasp of a plan to {math.degrees(FIGURE_GOAL):+.0f} deg"
            if reach.q_start is not None
            else "NO initial grasp"
        )
        fig = figure_model(scene, q=reach.q_start, reachable=reach.contacts, note=note)
    try:
        save_figure(fig, path, dpi=120)
    finally:
        plt.close(fig)


def run(args) -> int:
    from trajectotree.scene.plant import build_scene
    from trajectotree.scene.spatial import is_space_hand

    if args.hand is not None and is_space_hand(args.hand):
        return run_space(args)
    if args.figure:
        check_output_file("--figure", args.figure, FIGURE_SUFFIXES)
    config = config_from_args(args)
    scene = build_scene(config.scene)
    reach = object_reach(scene, config.search)
    summary = summarize(scene, reach.to_json(config.search))
    if args.rotations and reach.grasps.candidates:
        from trajectotree.search.workspace import rotation_range

        summary["reach"]["rotations"] = rotation_range(scene, config.search).to_json()
    if args.figure:
        draw_model(scene, args.figure, reach)
        summary["figure"] = args.figure
    if args.json:
        print_json(summary)
    else:
        o = summary["object"]
        size = f"{o['size_m'][0]:.3f} x {o['size_m'][1]:.3f} m box" if "size_m" in o else o["name"]
        print(
            f"object: {size}, {o['mass_kg']:.3f} kg, I_zz {o['inertia_zz_kg_m2']:.3g} kg m^2, mu {o['mu']}; "
            f"gravity {summary['gravity_W']}"
        )
        if o["kind"] == "polygon":
            print(
                f"  vertices (m, counter-clockwise about the centroid): {o['vertices_m']}; "
                f"area {o['area_m2']:.4g} m^2, perimeter {o['perimeter_m']:.4g} m"
            )
        for i, f in enumerate(summary["fingers"]):
            print(
                f"finger {i}: base {f['base_W']} m, links {f['link_lengths_m']} m, "
                f"q in [{f['q_lower']}, {f['q_upper']}] rad, |tau| <= {f['tau_max']} N m"
            )
        print(reach_line(summary["reach"]))
        if summary["reach"]["payload"] is not None:
            print(payload_line(summary["reach"], o["mass_kg"]))
        if summary["reach"]["workspace"] is not None:
            print(workspace_line(summary["reach"]))
        if "rotations" in summary["reach"]:
            print(rotations_line(summary["reach"]["rotations"]))
        if args.figure:
            print(f"figure: {args.figure}")
    return 0


# -- a hand in space (scene.spatial) ------------------------------------------------------------
def space_summary(scene) -> dict:
    """The box, the fingers, which faces each finger reaches and each fingertip's workspace."""
    from trajectotree.search.spatial_reach import face_reach, fingertip_workspace

    box, workspace = scene.object, fingertip_workspace(scene)
    return {
        "kind": "space",
        "object": {"size_m": list(box.size), "mass_kg": box.mass, "mu": box.mu},
        "gravity_W": scene.plant.gravity_field().gravity_vector().tolist(),
        "num_positions": scene.plant.num_positions(),
        "num_actuators": scene.plant.num_actuators(),
        "tip_radius_m": scene.tip_radius,
        "fingers": [
            {
                "base_W": f.p_W_joint[0].round(6).tolist(),
                "q_lower": f.q_lower.tolist(),
                "q_upper": f.q_upper.tolist(),
                "tau_max": scene.tau_max[i].tolist(),
                "tip_workspace_W": workspace[i].round(4).tolist(),
            }
            for i, f in enumerate(scene.fingers)
        ],
        "reach": face_reach(scene).to_json(),
    }


def space_initial_grasps(scene, config) -> dict:
    """How many initial grasps the search finds at the grasp point (search.space_tree.space_initial_grasp, the check
    `search` and `plan` refuse a box by: cli.space_options.check_space_graspable), at mu_plan."""
    from trajectotree.config import mu_plan
    from trajectotree.scene.spatial import START_POSE
    from trajectotree.search.space_tree import space_initial_grasp

    mu = mu_plan(config.scene, config.search)
    plan = space_initial_grasp(scene, START_POSE[:4], config.search, mu)
    return {"count": plan.stats.initial_grasp_candidates, "mu_plan": mu}


def run_space(args) -> int:
    """`trajectotree scene` for a hand in space: the plant's summary and each finger's reach."""
    from trajectotree.cli.space_options import build_args_scene, space_config
    from trajectotree.search.spatial_reach import CLEARANCE

    config = space_config(args)
    scene = build_args_scene(args, config)
    summary = space_summary(scene) | {"initial_grasps": space_initial_grasps(scene, config)}
    if args.json:
        print_json(summary)
        return 0
    o, reach = summary["object"], summary["reach"]
    print(
        f"object: {' x '.join(f'{s:.3f}' for s in o['size_m'])} m box, {o['mass_kg']:.3f} kg, mu {o['mu']}, "
        f"on a free (quaternion) joint at the grasp point; gravity {summary['gravity_W']}"
    )
    for i, f in enumerate(summary["fingers"]):
        low, high = f["tip_workspace_W"]
        print(
            f"finger {i}: base {f['base_W']} m, q in [{f['q_lower']}, {f['q_upper']}] rad, "
            f"|tau| <= {f['tau_max']} N m; "
            f"fingertip workspace x {low[0]:+.3f}..{high[0]:+.3f}, y {low[1]:+.3f}..{high[1]:+.3f}, "
            f"z {low[2]:+.3f}..{high[2]:+.3f} m"
        )
    n = reach["contacts_per_face"]
    print(f"reach at the start (of {n} contacts per face, IK with the links {CLEARANCE * 1000:g} mm clear of the box):")
    print("  finger  " + "  ".join(f"{name:>3}" for name in reach["faces"]))
    for i, row in enumerate(reach["reachable_contacts"]):
        print(f"  {i:6d}  " + "  ".join(f"{c:3d}" for c in row))
    per_face = ", ".join(f"{name} {k}" for name, k in zip(reach["faces"], reach["fingers_per_face"]))
    print(f"fingers reaching each face: {per_face}")
    grasps = summary["initial_grasps"]
    print(
        f"initial grasps at the grasp point (the search's roots at mu_plan {grasps['mu_plan']:.3g}): "
        + (str(grasps["count"]) if grasps["count"] else "NONE: `search` and `plan` refuse this box")
    )
    return 0
