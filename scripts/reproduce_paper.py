"""Reproduce the paper's experiment (Sec. IV, Figs. 2-3) in one command.

60 goal rotations drawn uniformly in [-pi, pi] with seed 0; each planned with TrajectoTree,
CITO and CITO warm-start and executed in simulation under both controllers (the grasp
controller and the paper's eq. 20); TrajectoTree's plans also under model mismatch and a push
(trajectotree.experiments.executions); then the figures (PNG + PDF) and the tables (Markdown + CSV).
The same as

    trajectotree sweep --goals 60 --seed 0 --controllers grasp paper --out SWEEP_DIR
    (the TrajectoTree plans under grasp x mismatch, push: trajectotree.experiments.executions.run_executions)
    trajectotree report SWEEP_DIR --out REPORT_DIR

The plans are made first (the sweep), the executions after them (a post-pass over the saved
plans), so the planning sweep does not depend on the controller's settings.

Resumable: rerun the same command after an interruption and finished trials are kept.
Trials run on local processes (--workers) or on a Dask cluster (--scheduler).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from trajectotree.config import Config, ConfigError
from trajectotree.config.executor import Executor
from trajectotree.experiments.executions import PAPER_EXECUTORS, run_executions
from trajectotree.experiments.report import make_report, table_markdown
from trajectotree.experiments.sweep import METHODS, SweepSpec, run_sweep


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--out", default="paper-sweep", metavar="SWEEP_DIR", help="sweep directory (default: %(default)s)"
    )
    parser.add_argument(
        "--report-dir",
        default="docs/results",
        metavar="DIR",
        help="where the figures and the table go (default: %(default)s)",
    )
    parser.add_argument("--goals", type=int, default=60, help="number of goals (default: 60, the paper's)")
    parser.add_argument("--seed", type=int, default=0, help="goal sampler seed (default: 0)")
    parser.add_argument("--workers", type=int, help="local worker processes (default: the number of CPUs)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler to run the trials on")
    parser.add_argument("--time-limit", type=float, default=1800.0, metavar="S", help="per-trial limit, s")
    args = parser.parse_args()
    try:
        spec = SweepSpec(
            goals=args.goals,
            seed=args.seed,
            methods=METHODS,
            simulate=False,
            config=Config(),
            time_limit_s=args.time_limit,
        )
        start = time.perf_counter()
        summary = run_sweep(spec, args.out, workers=args.workers, scheduler=args.scheduler)
        settings = {"gains": spec.config.controller, "sim": spec.config.sim, "workers": args.workers}
        run_executions(args.out, executors=PAPER_EXECUTORS, conditions=["nominal"], **settings)
        run_executions(
            args.out, executors=[Executor.GRASP], conditions=["mismatch", "push"], methods=["trajectotree"], **settings
        )
        files, table = make_report(args.out, args.report_dir)
    except ConfigError as e:
        print(f"reproduce_paper: error: {e}", file=sys.stderr)
        return 2
    print(summary.line())
    print(table_markdown(table), end="")
    figures = (
        files.figure_time_cost
        + (files.figure_tracking or ())
        + tuple(path for pair in files.figure_tracking_by_controller.values() for path in pair)
    )
    print(f"figures: {', '.join(figures)}")
    if files.executions_md:
        print(Path(files.executions_md).read_text(), end="")
    print(f"table: {files.table_md}, {files.table_csv}; wall time {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
