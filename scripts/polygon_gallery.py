"""Objects beyond the paper's box: plan and execute five convex polygons, write the gallery.

For each shape (an equilateral triangle of side 0.14 m, a regular pentagon and hexagon of
circumradius 0.07 m, a 0.24 x 0.06 m bar and an irregular quadrilateral), a sweep of TrajectoTree
over 12 goals uniform in [-pi, pi] (seed 0), each plan executed with the default controller; then
one keyframe figure per shape (its first planned goal) and a Markdown table. The same as, per shape,

    trajectotree sweep --polygon "x1,y1 x2,y2 ..." --goals 12 --seed 0 --methods trajectotree --simulate --out DIR

Resumable (rerun the same command: finished trials are kept).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

from trajectotree.config import Config, ConfigError, ObjectConfig, SceneConfig
from trajectotree.experiments.report import load_sweep
from trajectotree.experiments.sweep import SweepSpec, run_sweep


def regular(sides: int, circumradius: float) -> tuple[tuple[float, float], ...]:
    """A regular polygon with a vertex straight down (a face on top for even sides)."""
    angles = -math.pi / 2 + 2 * math.pi * np.arange(sides) / sides
    return tuple((round(circumradius * math.cos(a), 6), round(circumradius * math.sin(a), 6)) for a in angles)


SHAPES = {
    "triangle": regular(3, 0.14 / math.sqrt(3)),  # side 0.14 m
    "pentagon": regular(5, 0.07),
    "hexagon": regular(6, 0.07),
    "bar": ((-0.12, -0.03), (0.12, -0.03), (0.12, 0.03), (-0.12, 0.03)),
    "quadrilateral": ((-0.09, -0.05), (0.08, -0.06), (0.06, 0.06), (-0.05, 0.04)),
}


def shape_config(vertices) -> Config:
    return Config(scene=SceneConfig(object=ObjectConfig(vertices=tuple(vertices))))


def shape_row(name: str, vertices, rows: list[dict]) -> dict:
    simulated = [r for r in rows if r.get("simulated")]
    held = [r for r in simulated if not r.get("dropped")]
    mean = lambda key, rs: float(np.mean([r[key] for r in rs])) if rs else float("nan")  # noqa: E731
    return {
        "shape": name,
        "vertices": " ".join(f"{x:g},{y:g}" for x, y in vertices),
        "goals": len(rows),
        "planned": sum(bool(r.get("success")) for r in rows),
        "executed": len(simulated),
        "held": len(held),
        "errors": sum(r.get("error") is not None for r in rows),
        "mean_time_s": mean("total_time_s", [r for r in rows if r.get("total_time_s") is not None]),
        "mae_x_mm": 1e3 * mean("mae_x", simulated),
        "mae_y_mm": 1e3 * mean("mae_y", simulated),
        "mae_theta_rad": mean("mae_theta", simulated),
        "failures": "; ".join(
            f"goal {r['goal']:+.3f}: {short(r.get('error') or r.get('status'))}"
            + (" (dropped)" if r.get("dropped") else "")
            for r in rows
            if r.get("error") or not r.get("success") or r.get("dropped")
        ),
    }


def short(reason: str, limit: int = 240) -> str:
    """A trial's reason, cut to `limit` characters for the table's notes (trial.json has it all)."""
    return reason if len(reason) <= limit else reason[:limit].rsplit(" ", 1)[0] + " ..."


def table_markdown(table: list[dict]) -> str:
    lines = [
        "| shape | vertices (m) | planned (physics check passed) | executed without a drop | mean planning "
        "time [s] | MAE x [mm] | MAE y [mm] | MAE theta [rad] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in table:
        lines.append(
            f"| {s['shape']} | `{s['vertices']}` | {s['planned']}/{s['goals']} | {s['held']}/{s['goals']} | "
            f"{s['mean_time_s']:.2f} | {s['mae_x_mm']:.2f} | {s['mae_y_mm']:.2f} | {s['mae_theta_rad']:.3f} |"
        )
    notes = [f"- {s['shape']}: {s['failures']}" for s in table if s["failures"]]
    return "\n".join(lines) + "\n" + ("\nNot planned or dropped:\n" + "\n".join(notes) + "\n" if notes else "")


def keyframe_figure(sweep_dir: Path, rows: list[dict], config: Config, path: Path) -> str | None:
    """The keyframes of the shape's first planned goal (figures.figure_keyframes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.config import mu_plan
    from trajectotree.figures.run import figure_keyframes, save_figure
    from trajectotree.io import load_plan
    from trajectotree.scene.plant import build_scene

    planned = sorted((r for r in rows if r.get("success")), key=lambda r: r["goal_index"])
    if not planned:
        return None
    contact_plan = load_plan(sweep_dir / "trials" / planned[0]["key"]).contact_plan
    if not math.isfinite(contact_plan.mu_plan):  # plan.json from before it recorded mu_plan
        contact_plan = dataclasses.replace(contact_plan, mu_plan=mu_plan(config.scene, config.search))
    fig = figure_keyframes(build_scene(config.scene), contact_plan)
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="polygon-sweeps", metavar="DIR", help="one sweep folder per shape in here")
    parser.add_argument(
        "--report-dir",
        default="docs/results/polygons",
        metavar="DIR",
        help="where the figures and the table go (default: %(default)s)",
    )
    parser.add_argument("--goals", type=int, default=12, help="goals per shape (default: 12)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--shapes", default=",".join(SHAPES), help=f"comma-separated, from {', '.join(SHAPES)}")
    parser.add_argument("--workers", type=int, help="local worker processes (default: the number of CPUs)")
    args = parser.parse_args()
    names = [s.strip() for s in args.shapes.split(",")]
    unknown = [s for s in names if s not in SHAPES]
    if unknown:
        print(f"polygon_gallery: error: unknown shape(s) {unknown}; valid: {', '.join(SHAPES)}", file=sys.stderr)
        return 2
    report = Path(args.report_dir)
    report.mkdir(parents=True, exist_ok=True)
    start, table = time.perf_counter(), []
    try:
        for name in names:
            config = shape_config(SHAPES[name])
            spec = SweepSpec(goals=args.goals, seed=args.seed, methods=("trajectotree",), simulate=True, config=config)
            sweep_dir = Path(args.out) / name
            print(run_sweep(spec, sweep_dir, workers=args.workers).line())
            _, rows = load_sweep(sweep_dir)
            table.append(shape_row(name, SHAPES[name], rows))
            figure = keyframe_figure(sweep_dir, rows, config, report / f"{name}.png")
            print(
                f"{name}: {table[-1]['planned']}/{args.goals} planned, {table[-1]['held']}/{args.goals} executed "
                f"without a drop; figure {figure}"
            )
    except ConfigError as e:
        print(f"polygon_gallery: error: {e}", file=sys.stderr)
        return 2
    text = table_markdown(table)
    (report / "results.md").write_text(text)
    print(text, end="")
    print(f"table: {report / 'results.md'}; wall time {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
