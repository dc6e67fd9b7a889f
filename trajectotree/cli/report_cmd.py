"""`trajectotree report SWEEP_DIR`: the paper's Figs. 2-3 (PNG and PDF) and a summary
table (Markdown and CSV) beside the paper's numbers, from a sweep's finished trials."""

from __future__ import annotations

from pathlib import Path

from trajectotree.cli.common import check_output_dir, print_json


def register(subparsers) -> None:
    p = subparsers.add_parser("report", help="figures and summary table of a sweep", description=__doc__)
    p.add_argument("sweep_dir", metavar="SWEEP_DIR", help="directory written by `trajectotree sweep`")
    p.add_argument("--out", metavar="DIR", help="where to write (default: SWEEP_DIR/report)")
    p.add_argument("--json", action="store_true", help="print the table and file paths as JSON")
    p.set_defaults(run=run)


def run(args) -> int:
    from trajectotree.experiments.report import REPORT_DIR, make_report, space_table_markdown, table_markdown

    out = args.out or str(Path(args.sweep_dir) / REPORT_DIR)
    check_output_dir("--out" if args.out else "the report folder (default: SWEEP_DIR/report)", out)
    files, table = make_report(args.sweep_dir, out)
    if args.json:
        print_json({"files": files.__dict__, "table": table})
        return 0
    if files.kind == "space":
        print(space_table_markdown(table), end="")
        print(f"table: {files.table_md}, {files.table_csv}")
        if files.executions_md:
            print(f"executions: {files.executions_md} (per method, executor and world)")
            print(f"final orientation error per goal and world: {', '.join(files.figure_final_error)}")
        else:
            print("executions: none, the sweep ran without --simulate or --controllers")
        return 0
    print(table_markdown(table), end="")
    print(f"Fig. 2 (planning time, cost): {', '.join(files.figure_time_cost)}")
    if files.figure_tracking:
        print(f"Fig. 3 (tracking errors):     {', '.join(files.figure_tracking)}")
    for controller, paths in files.figure_tracking_by_controller.items():
        print(f"Fig. 3, {controller + ' controller:':<19} {', '.join(paths)}")
    if not files.figure_tracking and not files.figure_tracking_by_controller:
        print("Fig. 3 (tracking errors):     none, the sweep ran without --simulate or --controllers")
    print(f"table: {files.table_md}, {files.table_csv}")
    if files.executions_md:
        print(f"executions: {files.executions_md} (per method, controller and condition)")
    return 0
