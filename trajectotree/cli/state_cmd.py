"""`trajectotree state RUN_DIR --time T`: the executed run's state at time T (its sim.npz), as a
start.json that `trajectotree plan --start` plans from: the object's pose and velocity and the
joint angles (the contacts are derived from the fingertips when planning)."""

from __future__ import annotations

from trajectotree.cli.common import check_output_file


def register(subparsers) -> None:
    p = subparsers.add_parser("state", help="save a run's state at a time as a start for planning", description=__doc__)
    p.add_argument("run_dir", metavar="RUN_DIR", help="a folder with sim.npz (from `simulate` or `demo`)")
    p.add_argument("--time", type=float, required=True, metavar="T", help="time in the run, s")
    p.add_argument("--out", default="start.json", metavar="FILE.json", help="where to write it (default start.json)")
    p.set_defaults(run=run)


def run(args) -> int:
    from trajectotree.config import check_range
    from trajectotree.io import load_sim, save_start
    from trajectotree.start import StartState

    out = check_output_file("--out", args.out, (".json",))
    sim = load_sim(args.run_dir)
    check_range("--time", args.time, float(sim.t[0]), float(sim.t[-1]))
    start = StartState.from_run(sim.t, sim.x, sim.q, args.time)
    save_start(start, out)
    x = start.object_pose
    print(f"wrote {out}: object at x {x[0]:+.4f} m, y {x[1]:+.4f} m, theta {x[2]:+.4f} rad (t = {args.time:g} s)")
    return 0
