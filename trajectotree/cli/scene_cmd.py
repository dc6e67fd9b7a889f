"""`trajectotree scene`: build the plant from the models and a config, print a summary."""

from __future__ import annotations

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
    """The hand and box (figures.figure_model), written atomically."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.figures import figure_model, save_figure
    fig = figure_model(scene)
    try:
        save_figure(fig, path, dpi=120)
    finally:
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
