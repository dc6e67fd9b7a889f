"""`trajectotree scene`: build the plant from the models and a config, print a summary."""

from __future__ import annotations

import numpy as np

from trajectotree.cli.common import (FIGURE_SUFFIXES, add_config_options, check_output_file, config_from_args,
                                      print_json)


def register(subparsers) -> None:
    p = subparsers.add_parser("scene", help="build the hand and box plant and summarize it",
                              description=__doc__)
    add_config_options(p, segments=False)
    p.add_argument("--figure", metavar="FILE.png", help="draw the model (hand, box, reach circles); .png, .pdf or .svg")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(run=run)


def summarize(scene) -> dict:
    c = scene.config
    body = scene.plant.GetBodyByName("box", scene.box)
    return {
        "box": {"size_m": [c.box_width, c.box_height], "mass_kg": body.default_mass(), "mu": c.mu},
        "gravity_W": scene.plant.gravity_field().gravity_vector().tolist(),
        "num_positions": scene.plant.num_positions(),
        "num_actuators": scene.plant.num_actuators(),
        "tip_radius_m": scene.tip_radius,
        "fingers": [{"base_W": f.p_W_base.round(6).tolist(), "link_lengths_m": [round(f.l1, 6), round(f.l2, 6)],
                     "q_lower": f.q_lower.tolist(), "q_upper": f.q_upper.tolist(), "tau_max": f.tau_max.tolist()}
                    for f in scene.fingers],
    }


def draw_model(scene, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.figures import plot_box, plot_hand, plot_workspace
    fig, ax = plt.subplots(figsize=(5, 5))
    c = scene.config
    plot_box(ax, c.box_width, c.box_height, c.initial_pose)
    for f in scene.fingers:
        plot_workspace(ax, f)
    plot_hand(ax, scene, np.tile([0.25, 1.2], 4))
    for i, f in enumerate(scene.fingers):
        ax.annotate(f"finger {i}", f.p_W_base, textcoords="offset points", xytext=(0, 8), ha="center", fontsize=8)
    ax.annotate("", xy=(0.0, -0.27), xytext=(0.0, -0.2), arrowprops={"arrowstyle": "->"})
    ax.text(0.005, -0.24, "g", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlim(-0.3, 0.3)
    ax.set_ylim(-0.3, 0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Planar four-finger hand and 0.20 x 0.10 m box")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args) -> int:
    from trajectotree.scene import build_scene
    if args.figure:
        check_output_file("--figure", args.figure, FIGURE_SUFFIXES)
    scene = build_scene(config_from_args(args).scene)
    summary = summarize(scene)
    if args.figure:
        draw_model(scene, args.figure)
        summary["figure"] = args.figure
    if args.json:
        print_json(summary)
    else:
        b = summary["box"]
        print(f"box {b['size_m'][0]:.3f} x {b['size_m'][1]:.3f} m, {b['mass_kg']:.3f} kg, mu {b['mu']}; "
              f"gravity {summary['gravity_W']}")
        for i, f in enumerate(summary["fingers"]):
            print(f"finger {i}: base {f['base_W']} m, links {f['link_lengths_m']} m, "
                  f"q in [{f['q_lower']}, {f['q_upper']}] rad, |tau| <= {f['tau_max']} N m")
        if args.figure:
            print(f"figure: {args.figure}")
    return 0
