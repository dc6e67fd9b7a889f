"""`trajectotree search`: the contact-sequence planner alone (paper Sec. III-A, Algorithm 1).

Prints the plan (or why none was found) and the search statistics; exits 0 whether or
not a plan was found (`"success": false` with a reason), 2 on invalid input.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

from trajectotree.cli.common import (FIGURE_SUFFIXES, add_config_options, check_goal, check_output_file,
                                      config_from_args, print_json)
from trajectotree.io import write_bytes_atomic


def register(subparsers) -> None:
    p = subparsers.add_parser("search", help="find a finger-gaiting contact sequence for a goal rotation",
                              description=__doc__)
    p.add_argument("--goal", type=float, required=True, metavar="RAD", help="goal rotation of the box, rad, in [-pi, pi]")
    add_config_options(p)
    p.add_argument("--figure", metavar="FILE.png",
                   help="draw the sequence as keyframes (like the paper's Fig. 1); .png, .pdf or .svg")
    p.add_argument("--json", action="store_true",
                   help="print the plan as JSON (each node: object_pose, q, switching_finger, contacts)")
    p.set_defaults(run=run)


def draw_plan(scene, plan, path: str) -> None:
    """One panel per node; written to a temporary name first, then moved into place."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.plotting import contact_node_legend_handles, plot_contact_node
    cols = min(5, len(plan.nodes))
    rows = math.ceil(len(plan.nodes) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(max(2.6 * cols, 7.0), 2.6 * rows + 0.9), squeeze=False)
    for n, ax in enumerate(axes.flat):
        ax.set_axis_off()
        if n >= len(plan.nodes):
            continue
        node = plan.nodes[n]
        plot_contact_node(ax, scene, node, mu=scene.config.mu, previous=plan.nodes[n - 1] if n else None)
        ax.set_aspect("equal")
        ax.set_xlim(-0.26, 0.26)
        ax.set_ylim(-0.26, 0.26)
        moved = "initial grasp" if n == 0 else ("no switch" if node.switching_finger is None
                                                 else f"finger {node.switching_finger} moves")
        ax.set_title(f"n={n}  theta={node.object_pose[2]:+.2f}\n{moved}", fontsize=8)
    fig.suptitle(f"contact sequence for goal {plan.goal:+.3f} rad (switching finger drawn thick)", fontsize=10)
    handles = contact_node_legend_handles(scene.config.mu)
    ncol = 3 if cols >= 4 else 2
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    height = fig.get_figheight()  # inches: the legend's rows below, the title above
    fig.tight_layout(rect=(0, (0.2 * math.ceil(len(handles) / ncol) + 0.1) / height, 1, 1 - 0.3 / height))
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format=Path(path).suffix.lstrip(".").lower() or "png", dpi=110)
    finally:
        plt.close(fig)
    write_bytes_atomic(path, buffer.getvalue())


def run(args) -> int:
    from trajectotree.scene import build_scene
    from trajectotree.search import find_contact_plan
    goal = check_goal(args.goal)
    config = config_from_args(args)
    if args.figure:
        check_output_file("--figure", args.figure, FIGURE_SUFFIXES)
    scene = build_scene(config.scene)
    plan = find_contact_plan(scene, goal, config.search)
    if args.figure and plan.success:
        draw_plan(scene, plan, args.figure)
    if args.json:
        print_json(plan.to_json())
        return 0
    s = plan.stats
    print(f"goal {goal:+.4f} rad, N = {config.search.num_nodes}: "
          f"{'plan found' if plan.success else 'no plan: ' + plan.reason}")
    print(f"search {s.time_s:.3f} s, {s.expanded} nodes expanded, {s.generated} generated, "
          f"{s.lp_calls} LP and {s.ik_calls} IK solves; {s.initial_grasps_searched} of "
          f"{s.initial_grasp_candidates} candidate initial grasps searched")
    print(f"friction: scene mu {config.scene.mu:g}, planned with mu_plan {plan.mu_plan:.3g} "
          f"(search.friction_safety {config.search.friction_safety:g}); required mu = the least friction at "
          f"which the grasp / the three fingers holding during the switch are in form closure")
    for n, node in enumerate(plan.nodes):
        moved = "-" if node.switching_finger is None else str(node.switching_finger)
        contacts = " ".join(f"{v:.3f}" for v in node.arclengths)
        stance = "" if node.stance_required_mu is None else f"  stance required mu {node.stance_required_mu:.3f}"
        print(f"  node {n}: theta {node.object_pose[2]:+.3f}  switching finger {moved}  "
              f"arclengths [{contacts}] m  closure margin {node.closure_margin:.3f}  "
              f"required mu {node.required_mu:.3f}{stance}")
    if args.figure:
        print(f"figure: {args.figure}" if plan.success else "figure: not drawn (no plan)")
    return 0
