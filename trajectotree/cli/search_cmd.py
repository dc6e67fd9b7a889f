"""`trajectotree search`: the contact-sequence planner alone (paper Sec. III-A, Algorithm 1).

Prints the plan (or why none was found) and the search statistics; exits 0 whether or
not a plan was found (`"success": false` with a reason), 2 on invalid input.

A hand in space (`--hand fingerpro4`, or a description of kind: space) takes its goal orientation as
`--goal-quat W X Y Z` (Drake's order, normalized) or `--goal-rpy R P Y` (rad, Drake's RollPitchYaw),
the cube's position unchanged (trajectotree.search.space_tree).
"""

from __future__ import annotations

import dataclasses
import math

from trajectotree.cli.common import (
    FIGURE_SUFFIXES,
    add_config_options,
    add_goal_options,
    check_goal_workspace,
    check_output_file,
    check_payload,
    config_from_args,
    goal_from_args,
    print_json,
    reason_lines,
)
from trajectotree.cli.space_goal import add_space_goal_options, refuse_space_goal_on_planar_hand, space_goal


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "search", help="find a finger-gaiting contact sequence for a goal rotation or pose", description=__doc__
    )
    add_goal_options(p)
    add_space_goal_options(p)
    add_config_options(p, space=True)
    p.add_argument(
        "--figure",
        metavar="FILE.png",
        help="draw the sequence as keyframes (like the paper's Fig. 1); .png, .pdf or .svg",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the plan as JSON (each node: object_pose, q, switching_finger, contacts)",
    )
    p.set_defaults(run=run)


def draw_plan(scene, plan, path: str) -> None:
    """The keyframes of `plan` (figures.figure_keyframes; in space figures.space.figure_space_keyframes), written
    atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.contact_plan import SpaceContactPlan
    from trajectotree.figures.run import figure_keyframes, save_figure

    if isinstance(plan, SpaceContactPlan):
        from trajectotree.figures.space import figure_space_keyframes

        fig = figure_space_keyframes(scene, plan)
    else:
        fig = figure_keyframes(scene, plan)
    try:
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def run(args) -> int:
    from trajectotree.config import with_segments
    from trajectotree.scene.plant import build_scene
    from trajectotree.scene.spatial import is_space_hand
    from trajectotree.search.tree import find_contact_plan

    if args.hand is not None and is_space_hand(args.hand):
        return run_space(args)
    refuse_space_goal_on_planar_hand(args)
    config = config_from_args(args)
    goal = goal_from_args(args, config)
    if args.figure:
        check_output_file("--figure", args.figure, FIGURE_SUFFIXES)
    scene = build_scene(config.scene)
    check_payload(scene, config, args)
    check_goal_workspace(scene, config, goal, args)
    config = dataclasses.replace(config, search=with_segments(config.search, config.scene.initial_pose, goal))
    plan = find_contact_plan(scene, goal, config.search)
    if args.figure and plan.success:
        draw_plan(scene, plan, args.figure)
    if args.json:
        print_json(plan.to_json())
        return 0
    s = plan.stats
    summary, details = reason_lines(plan.reason)
    where = "" if goal.position is None else f" at ({goal.position[0]:+.4f}, {goal.position[1]:+.4f}) m"
    print(
        f"goal {goal.theta:+.4f} rad{where}, N = {config.search.num_nodes}: "
        f"{'plan found' if plan.success else 'no plan: ' + summary}"
    )
    for line in details:
        print(f"  {line}")
    print(
        f"search {s.time_s:.3f} s, {s.expanded} nodes expanded, {s.generated} generated, "
        f"{s.lp_calls} LP and {s.ik_calls} IK solves; {s.initial_grasps_searched} of "
        f"{s.initial_grasp_candidates} candidate initial grasps searched"
    )
    print(
        f"friction: scene mu {config.scene.mu:g}, planned with mu_plan {plan.mu_plan:.3g} "
        f"(search.friction_safety {config.search.friction_safety:g}); required mu = the least friction at "
        f"which the grasp / the three fingers holding during the switch are in form closure; a stance resists the "
        f"hardest push along +-x and +-y that it holds against ({config.search.push_normal_force:g} N a finger, "
        f"the motors' torques)"
    )
    for n, node in enumerate(plan.nodes):
        moved = "-" if node.switching_finger is None else str(node.switching_finger)
        contacts = " ".join(f"{v:.3f}" for v in node.arclengths)
        stance = "" if node.stance_required_mu is None else f"  stance required mu {node.stance_required_mu:.3f}"
        if node.stance_push_capacity is not None:
            stance += f"  stance resists a {node.stance_push_capacity:.1f} N push"
        xy = "" if goal.position is None else f"x {node.object_pose[0]:+.4f}  y {node.object_pose[1]:+.4f}  "
        print(
            f"  node {n}: {xy}theta {node.object_pose[2]:+.3f}  switching finger {moved}  "
            f"arclengths [{contacts}] m  closure margin {node.closure_margin:.3f}  "
            f"required mu {node.required_mu:.3f}{stance}"
        )
    if args.figure:
        print(f"figure: {args.figure}" if plan.success else "figure: not drawn (no plan)")
    return 0


# -- a hand in space ------------------------------------------------------------------------------
def run_space(args) -> int:
    """`trajectotree search` for a hand in space: Algorithm 1 in space toward the goal orientation."""
    from trajectotree.cli.space_options import build_args_scene, check_space_graspable, space_config
    from trajectotree.config import mu_plan
    from trajectotree.search.space_tree import find_space_contact_plan

    goal = space_goal(args)
    if args.figure:
        check_output_file("--figure", args.figure, FIGURE_SUFFIXES)
    config = space_config(args)
    mu = mu_plan(config.scene, config.search)
    scene = build_args_scene(args, config)
    check_space_graspable(scene, config, args)
    plan = find_space_contact_plan(scene, goal, config.search, mu)
    if args.figure and plan.success:
        draw_plan(scene, plan, args.figure)
    if args.json:
        print_json(plan.to_json())
        return 0
    s = plan.stats
    summary, details = reason_lines(plan.reason)
    w, x, y, z = plan.goal
    outcome = "plan found" if plan.success else "no plan: " + summary
    print(
        f"goal quaternion [{w:+.4f}, {x:+.4f}, {y:+.4f}, {z:+.4f}], nodes at most "
        f"{math.degrees(plan.max_segment_rotation):g} deg apart: {outcome}"
    )
    for line in details:
        print(f"  {line}")
    print(
        f"search {s.time_s:.3f} s, {s.expanded} nodes expanded, {s.generated} generated, {s.lp_calls} LP and "
        f"{s.ik_calls} IK solves; {s.initial_grasps_searched} of {s.initial_grasp_candidates} initial grasps searched; "
        f"mu_plan {plan.mu_plan:.3g}"
    )
    for n, node in enumerate(plan.nodes):
        moved = "-" if node.switching_finger is None else str(node.switching_finger)
        quat = " ".join(f"{v:+.3f}" for v in node.object_pose[:4])
        contacts = "  ".join(
            f"{face} ({', '.join(f'{v * 1000:+.1f}' for v in p)}) mm" for face, p in zip(node.faces, node.p_BC)
        )
        stance = "" if node.stance_torque is None else f"  stance {node.stance_torque:.3f} N m"
        if node.stance_push_capacity is not None:
            stance += f", resists {node.stance_push_capacity:.2f} N"
        print(f"  node {n}: quat [{quat}]  switching finger {moved}  contacts (B) {contacts}{stance}")
        print(f"          q {' '.join(f'{v:+.3f}' for v in node.q.ravel())} rad")
    if args.figure:
        print(f"figure: {args.figure}" if plan.success else "figure: not drawn (no plan)")
    return 0
