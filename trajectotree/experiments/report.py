"""The paper's figures and a summary table from a sweep directory (Sec. IV, Figs. 2-3).

Fig. 2: box plots of total planning time (search + build + solve, every trial with a
plan result) and of the final cost (converged plans), per method, means as crosses.
Fig. 3: mean absolute error of the box's x, y and theta against the plan over time, per
method, with 95% Student-t confidence bands across the simulated trials.
Table: converged and physically valid rates, mean and median planning time, TrajectoTree's speedup over each
baseline (ratio of mean planning times, as the paper's 98 s / 14 s), mean cost, drop
rate and mean tracking errors, beside the paper's numbers where it gives them.
"""

from __future__ import annotations

import csv
import io
import json
import os
import secrets
import shutil
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trajectotree.config import ConfigError
from trajectotree.execution.metrics import mean_confidence_interval
from trajectotree.experiments.sweep_store import MANIFEST_FILE, TRIALS_DIR, read_rows
from trajectotree.figures.run import save_figure
from trajectotree.io import SIM_NPZ, write_bytes_atomic

METHOD_LABELS = {"trajectotree": "TrajectoTree", "cito": "CITO", "cito-warm": "CITO, warm-start"}
METHOD_COLORS = {"trajectotree": "tab:blue", "cito": "tab:orange", "cito-warm": "tab:green"}
# The paper's numbers (Sec. IV-C): mean total planning time over 60 goals, s.
PAPER_MEAN_TIME_S = {"trajectotree": 14.0, "cito": 98.0, "cito-warm": 76.0}
REFERENCE = "trajectotree"
REPORT_DIR = "report"  # the default output folder, SWEEP_DIR/report
STAGE_PREFIX = ".tmp-report-"  # a report being written (make_report's _staged)
# Fig. 3's panels: label, and the factor from sim.npz's units (m, m, rad) to the label's, as the tables show them.
ERROR_LABELS = ("x [mm]", "y [mm]", r"$\theta$ [rad]")
ERROR_SCALES = (1e3, 1e3, 1.0)
CONFIDENCE = 0.95
BAND_LABEL = f"shaded: {100 * CONFIDENCE:g} % CI of the mean (Student t, across trials)"


@dataclass(frozen=True)
class ReportFiles:
    figure_time_cost: tuple[str, str] | None  # PNG, PDF; None for a sweep in space (its summary says why)
    figure_tracking: tuple[str, str] | None
    table_md: str
    table_csv: str
    executions_md: str | None = None  # per method, controller and condition (trajectotree.experiments.executions)
    figure_tracking_by_controller: dict = field(default_factory=dict)  # controller -> (PNG, PDF), nominal runs
    kind: str = "plane"  # "space": a sweep of a hand in space (space_table_markdown's table)
    figure_final_error: tuple[str, str] | None = None  # space: each goal's final orientation error per world


def load_sweep(sweep_dir: str | Path) -> tuple[dict, list[dict]]:
    """(manifest, rows of the finished trials); ConfigError if it is not a sweep directory."""
    sweep_dir = Path(sweep_dir)
    path = sweep_dir / MANIFEST_FILE
    if not path.is_file():
        raise ConfigError(
            f"{str(sweep_dir)!r} is not a sweep directory (no {MANIFEST_FILE}); "
            "make one with `trajectotree sweep --out DIR`"
        )
    try:
        manifest = json.loads(path.read_text())
        if not isinstance(manifest, dict) or not isinstance(manifest.get("methods"), list):
            raise ValueError("not a sweep manifest (no list of methods)")
    except (OSError, UnicodeDecodeError, ValueError) as e:  # JSONDecodeError is a ValueError
        raise ConfigError(f"{str(path)!r} is unreadable ({type(e).__name__}: {e})") from None
    rows = read_rows(sweep_dir)  # CorruptTrialError names an unreadable trial.json
    if not rows:
        raise ConfigError(f"{str(sweep_dir)!r} has no finished trials yet")
    return manifest, rows


def _values(rows, field):
    return np.array([r[field] for r in rows if r.get(field) is not None], dtype=float)


def _mean_or_none(values: np.ndarray) -> float | None:
    return float(values.mean()) if values.size else None


def converged(row: dict) -> bool:
    """IPOPT converged (and the search found a plan, where used), physically valid or not;
    rows written before the physics check have only `success`, which meant that."""
    return bool(row.get("converged", row.get("success")))


def paired_speedup(rows: list[dict], method: str) -> tuple[float | None, int]:
    """(mean planning time of `method` / mean of TrajectoTree, over the goals both
    converged on; number of those goals). Pairing keeps a quick failure from counting as
    speed; convergence, not the physics check, is what the solve time measures (the
    baselines' converged plans may push from a distance: the success column tells)."""
    solved = {
        m: {r["goal_index"]: r["total_time_s"] for r in rows if r["method"] == m and converged(r)}
        for m in (method, REFERENCE)
    }
    common = sorted(set(solved[method]) & set(solved[REFERENCE]))
    if method == REFERENCE or not common:
        return None, len(common)
    return (
        float(np.mean([solved[method][g] for g in common])) / float(np.mean([solved[REFERENCE][g] for g in common])),
        len(common),
    )


def method_summary(rows: list[dict], method: str) -> dict:
    mine = [r for r in rows if r["method"] == method]
    times = _values(mine, "total_time_s")
    costs = _values([r for r in mine if converged(r)], "cost")
    simulated = [r for r in mine if r.get("simulated")]
    speedup, paired = paired_speedup(rows, method)
    paper_time = PAPER_MEAN_TIME_S.get(method)
    paper_speedup = (paper_time / PAPER_MEAN_TIME_S[REFERENCE]) if method != REFERENCE and paper_time else None
    return {
        "method": method,
        "label": METHOD_LABELS.get(method, method),
        "trials": len(mine),
        "errors": sum(r.get("error") is not None for r in mine),
        "converged_rate": sum(converged(r) for r in mine) / len(mine) if mine else None,
        "success_rate": sum(bool(r.get("success")) for r in mine) / len(mine) if mine else None,
        "mean_time_s": float(times.mean()) if times.size else None,
        "paper_mean_time_s": paper_time,
        "median_time_s": float(np.median(times)) if times.size else None,
        "speedup": speedup,
        "speedup_goals": paired,
        "paper_speedup": paper_speedup,
        "mean_cost": float(costs.mean()) if costs.size else None,
        "simulated": len(simulated),
        "drop_rate": sum(bool(r.get("dropped")) for r in simulated) / len(simulated) if simulated else None,
        **{f"mae_{c}": _mean_or_none(_values(simulated, f"mae_{c}")) for c in ("x", "y", "theta")},
    }


def summary_table(rows: list[dict], methods: list[str]) -> list[dict]:
    return [method_summary(rows, m) for m in methods]


def _fmt(value, spec: str, suffix: str = "") -> str:
    return "n/a" if value is None else f"{value:{spec}}{suffix}"


TABLE_NOTES = """
Planning time = search + program build + IPOPT solve, over every trial that returned a plan
(converged or not; trials that crashed or hit the time limit are counted under errors and left out).
Converged: IPOPT converged (and the search found a plan, where used). Physically valid: converged
and the plan's arrays pass the physics check (Newton-Euler at the contact points, friction cones at
mu_plan, no force from a fingertip more than 0.1 mm off the box).
Speedup = mean planning time of the baseline / mean of TrajectoTree, over the goals both converged on
(in parentheses: how many); the paper's is the ratio of its means (98 s / 14 s, 76 s / 14 s).
Mean cost over converged plans. Drop rate and mean absolute tracking errors (time means of
|simulated - planned| box pose, then means over trials) over the executed plans. The paper
gives its numbers for the mean planning times only; the rest it shows in Figs. 2-3.
"""


def table_markdown(table: list[dict]) -> str:
    header = (
        "| method | trials | errors | converged | physically valid | mean time [s] | paper [s] "
        "| median time [s] | speedup | paper speedup | mean cost | executed | drop rate "
        "| MAE x [mm] | MAE y [mm] | MAE theta [rad] |"
    )
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for s in table:
        mae_mm = [None if s[f"mae_{c}"] is None else 1e3 * s[f"mae_{c}"] for c in ("x", "y")]
        reference = s["method"] == REFERENCE
        cells = [
            s["label"],
            str(s["trials"]),
            str(s["errors"]),
            _fmt(s["converged_rate"], ".0%"),
            _fmt(s["success_rate"], ".0%"),
            _fmt(s["mean_time_s"], ".2f"),
            _fmt(s["paper_mean_time_s"], ".0f"),
            _fmt(s["median_time_s"], ".2f"),
            "-" if reference else _fmt(s["speedup"], ".1f", f"x ({s['speedup_goals']})"),
            "-" if reference else _fmt(s["paper_speedup"], ".1f", "x"),
            _fmt(s["mean_cost"], ".4g"),
            str(s["simulated"]),
            _fmt(s["drop_rate"], ".0%"),
            _fmt(mae_mm[0], ".2f"),
            _fmt(mae_mm[1], ".2f"),
            _fmt(s["mae_theta"], ".3f"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def table_csv(table: list[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(table[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: ("" if v is None else v) for k, v in s.items()} for s in table)
    return buffer.getvalue()


def figure_time_and_cost(rows: list[dict], methods: list[str]):
    """Fig. 2: planning time (left) and final cost (right) per method."""
    import matplotlib.pyplot as plt

    from trajectotree.figures.statistics import plot_boxes_with_means

    fig, (ax_time, ax_cost) = plt.subplots(1, 2, figsize=(8, 3.6))
    colors = [METHOD_COLORS.get(m, "0.6") for m in methods]
    by_method = {m: [r for r in rows if r["method"] == m] for m in methods}
    times = [_values(by_method[m], "total_time_s") for m in methods]
    costs = [_values([r for r in by_method[m] if converged(r)], "cost") for m in methods]
    for ax, samples in ((ax_time, times), (ax_cost, costs)):
        labels = [f"{METHOD_LABELS.get(m, m)}\n(n={s.size})" for m, s in zip(methods, samples)]
        plot_boxes_with_means(ax, samples, labels, colors=colors)
    ax_time.set_ylabel("total planning time [s]")
    ax_cost.set_ylabel("final cost (converged plans)")
    for ax in (ax_time, ax_cost):
        ax.grid(axis="y", alpha=0.3)
    if any(t.size for t in times):
        ax_time.legend(handles=[ax_time.lines[-1]], loc="upper left", fontsize=8)
    fig.tight_layout()
    return fig


def load_tracking(sweep_dir: Path, rows: list[dict]) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """method -> [(t (T,), abs_error (T, 3))] of the simulated trials; ConfigError
    naming a sim.npz that cannot be read."""
    return _tracks((r["method"], sweep_dir / TRIALS_DIR / r["key"]) for r in rows if r.get("simulated"))


def load_execution_tracking(records: list[dict], controller: str) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """method -> [(t, abs_error)] of the nominal executions under `controller`."""
    return _tracks(
        (r["method"], Path(r["folder"]))
        for r in records
        if r["controller"] == controller and r["condition"] == "nominal"
    )


def _tracks(method_folders) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """method -> [(t, abs_error)] read from each (method, folder)'s sim.npz."""
    tracks: dict[str, list] = {}
    for method, folder in method_folders:
        path = folder / SIM_NPZ
        try:
            with np.load(path) as data:
                tracks.setdefault(method, []).append((data["t"], data["abs_error"]))
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
            raise ConfigError(
                f"{str(path)!r} is unreadable ({type(e).__name__}: {e}); rerun the sweep with the same "
                "arguments to recompute it"
            ) from None
    return tracks


def tracking_bands(tracks: list[tuple[np.ndarray, np.ndarray]], grid: np.ndarray):
    """Mean and 95% CI of the absolute errors on a common time grid. Each trial is
    interpolated inside its own time span; at a grid time, only the trials that
    cover it count (equal configs give equal spans)."""
    samples = np.full((len(tracks), grid.size, 3), np.nan)
    for i, (t, err) in enumerate(tracks):
        inside = (grid >= t[0]) & (grid <= t[-1])
        samples[i, inside] = np.column_stack([np.interp(grid[inside], t, err[:, c]) for c in range(3)])
    mean, lower, upper = (np.full((grid.size, 3), np.nan) for _ in range(3))
    covered = ~np.isnan(samples[:, :, 0])
    for mask in np.unique(covered.T, axis=0):
        if not mask.any():
            continue
        columns = np.all(covered.T == mask, axis=1)
        ci = mean_confidence_interval(samples[mask][:, columns], CONFIDENCE, axis=0)
        mean[columns], lower[columns], upper[columns] = ci.mean, ci.lower, ci.upper
    return mean, lower, upper


def figure_tracking(tracks: dict[str, list], methods: list[str], title: str | None = None):
    """Fig. 3: mean absolute error of x, y (mm, as the tables) and theta (rad) over time, each method's
    mean with its 95 % Student-t confidence band (named in the legend)."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from trajectotree.figures.statistics import plot_mean_band

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
    all_t = [t for m in methods for t, _ in tracks.get(m, ())]
    step = min(float(np.median(np.diff(t))) for t in all_t if t.size > 1)
    grid = np.arange(0.0, max(t[-1] for t in all_t) + step / 2, step)
    for m in methods:
        if not tracks.get(m):
            continue
        mean, lower, upper = tracking_bands(tracks[m], grid)
        for c, ax in enumerate(axes):
            k = ERROR_SCALES[c]
            plot_mean_band(
                ax,
                grid,
                k * mean[:, c],
                k * lower[:, c],
                k * upper[:, c],
                color=METHOD_COLORS.get(m),
                label=f"{METHOD_LABELS.get(m, m)} mean (n={len(tracks[m])})",
            )
    for ax, label in zip(axes, ERROR_LABELS):
        ax.set_ylim(bottom=0.0)  # errors are >= 0; a t-interval of few trials reaches below
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"mean absolute error, {label}")
        ax.grid(alpha=0.3)
    handles, _ = axes[0].get_legend_handles_labels()
    if handles:  # below the panels, where it hides no curve; the band's entry grey, as each band is its curve's colour
        handles.append(Patch(facecolor="0.5", alpha=0.25, lw=0, label=BAND_LABEL))
        fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    missing = [METHOD_LABELS.get(m, m) for m in methods if not tracks.get(m)]
    if missing:  # named, rather than silently absent from the curves
        fig.text(0.5, 0.0, "no executed plans: " + ", ".join(missing), fontsize=8, color="0.45", ha="center")
    height = fig.get_figheight()  # inches: the legend's row, then the note's
    fig.tight_layout(rect=(0, (0.3 if handles else 0) / height + (0.2 if missing else 0) / height, 1, 1))
    if handles and missing:
        fig.legends[0].set_bbox_to_anchor((0.5, 0.2 / height), transform=fig.transFigure)
    return fig


def _save(fig, stem: Path) -> tuple[str, str]:
    import matplotlib.pyplot as plt

    png, pdf = (save_figure(fig, stem.with_suffix(f".{ext}")) for ext in ("png", "pdf"))
    plt.close(fig)
    return png, pdf


@contextmanager
def _staged(out: Path) -> Iterator[Path]:
    """A new folder beside `out` (inside it when it exists) to write out's files into: on
    success they move into `out` (the folder itself is renamed when `out` is new); on any error
    it is removed, and `out` is as it was: a report is written whole or not at all."""
    new = not out.exists()
    parent = out.parent if new else out
    parent.mkdir(parents=True, exist_ok=True)
    # Not named .*.tmp: the sweep removes such leftovers with unlink, which a folder refuses.
    stage = parent / f"{STAGE_PREFIX}{os.getpid()}-{secrets.token_hex(4)}"
    stage.mkdir()  # the usual mode (mkdtemp's would be 0o700, and stay so after the rename)
    try:
        yield stage
        if new:
            os.rename(stage, out)
        else:
            for path in sorted(stage.iterdir()):
                os.replace(path, out / path.name)
            stage.rmdir()
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


def space_method_summary(rows: list[dict], method: str) -> dict:
    """A method's planning in space: planned (searched, solved, checked, within the goal tolerance), checked,
    within 2 deg, and the planning time (every trial that returned a plan result) with its median's ratio
    over TrajectoTree's."""
    mine = [r for r in rows if r["method"] == method]
    times = _values(mine, "total_time_s")
    reference = _values([r for r in rows if r["method"] == REFERENCE], "total_time_s")
    errors = [r.get("final_error_deg") for r in mine]
    median = float(np.median(times)) if times.size else None
    planned = [r for r in mine if r.get("success")]
    return {
        "method": method,
        "label": METHOD_LABELS.get(method, method),
        "trials": len(mine),
        "errors": sum(r.get("error") is not None for r in mine),
        "planned": len(planned),
        "checked": sum(bool(r.get("check_passed")) for r in mine),
        "within_2_deg": sum(e is not None and e <= SPACE_GOAL_TOLERANCE_DEG for e in errors),
        # the planned trials' stances (nodes) that hold at the search's stance margin, of their stances
        "margin_stances": int(_values(planned, "margin_stances").sum()),
        "stances": int(_values(planned, "stances").sum()),
        "mean_time_s": float(times.mean()) if times.size else None,
        "median_time_s": median,
        "p90_time_s": float(np.percentile(times, 90)) if times.size else None,
        "median_ratio": None
        if method == REFERENCE or median is None or not reference.size
        else median / float(np.median(reference)),
    }


def space_table_markdown(table: list[dict]) -> str:
    header = (
        "| method | trials | errors | planned | checked | within 2 deg | stances at the margin | mean time [s] "
        "| median time [s] | p90 time [s] | median / TrajectoTree's |"
    )
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for s in table:
        cells = [
            s["label"],
            str(s["trials"]),
            str(s["errors"]),
            *(f"{s[k]}/{s['trials']}" for k in ("planned", "checked", "within_2_deg")),
            f"{s['margin_stances']}/{s['stances']}",
            _fmt(s["mean_time_s"], ".2f"),
            _fmt(s["median_time_s"], ".2f"),
            _fmt(s["p90_time_s"], ".2f"),
            "-" if s["method"] == REFERENCE else _fmt(s["median_ratio"], ".1f", "x"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


SPACE_GOAL_TOLERANCE_DEG = 2.0  # deg, planning.spatial.GOAL_TOLERANCE (that module imports Drake; this one does not)
SPACE_TABLE_NOTES = """
A sweep of a hand in space (planning only). Planned: the search found a contact sequence, every program
solved, the plan passed the 3D physics check (planning.physics.check_space_physics) and ends within 2 deg
of its goal orientation. Checked: the plan's arrays passed that check. Within 2 deg: the last knot's
orientation is at most 2 deg from the goal. Stances at the margin: of the planned trials' nodes, those whose stance
(node 0: the initial grasp) holds the cube within the motors at the search's stance margin friction
(search.space_stance_margin; all of them with none). Planning time = search + the programs (a trial's segments one
after another in its process), over every trial that returned a plan result; median / TrajectoTree's is
the ratio of the method's median planning time over TrajectoTree's, over all their trials.
The planar report's Fig. 2 (box plots of time and cost) and Fig. 3 (tracking errors) are not drawn for a
sweep in space: the programs in space report no cost, and its executions are in executions.md (with
`sweep --simulate` or `--controllers`), each goal's final orientation error per world in fig_final_error.
"""


def make_report(sweep_dir: str | Path, out_dir: str | Path | None = None) -> tuple[ReportFiles, list[dict]]:
    """Writes the figures and the table (default: SWEEP_DIR/report/), whole or not at all
    (ConfigError naming an unreadable input, nothing written); returns their paths and the
    table rows."""
    import matplotlib

    matplotlib.use("Agg")

    sweep_dir = Path(sweep_dir)
    manifest, rows = load_sweep(sweep_dir)
    methods = [m for m in manifest["methods"] if any(r["method"] == m for r in rows)]
    out = Path(out_dir) if out_dir is not None else sweep_dir / REPORT_DIR
    if out.exists() and not out.is_dir():
        raise ConfigError(f"the report folder {str(out)!r} is an existing file; remove it or give --out DIR")
    if "space" in manifest:
        return _space_report(sweep_dir, rows, methods, out)
    with _staged(out) as stage:
        table = summary_table(rows, methods)
        write_bytes_atomic(stage / "summary.md", (table_markdown(table) + TABLE_NOTES).encode())
        write_bytes_atomic(stage / "summary.csv", table_csv(table).encode())
        fig2 = _save(figure_time_and_cost(rows, methods), stage / "fig2_time_cost")
        tracks = load_tracking(sweep_dir, rows)
        fig3 = _save(figure_tracking(tracks, methods), stage / "fig3_tracking") if tracks else None
        executions_md, fig3_by_controller = _execution_report(sweep_dir, rows, methods, stage)

    def final(paths):  # where the staged files now are
        return None if paths is None else tuple(str(out / Path(p).name) for p in paths)

    files = ReportFiles(
        figure_time_cost=final(fig2),
        figure_tracking=final(fig3),
        table_md=str(out / "summary.md"),
        table_csv=str(out / "summary.csv"),
        executions_md=None if executions_md is None else str(out / Path(executions_md).name),
        figure_tracking_by_controller={c: final(paths) for c, paths in fig3_by_controller.items()},
    )
    return files, table


def _space_report(sweep_dir: Path, rows: list[dict], methods: list[str], out: Path) -> tuple[ReportFiles, list[dict]]:
    """summary.md (the table and SPACE_TABLE_NOTES) and summary.csv of a sweep in space and, when its plans were
    executed, executions.md / .csv (per method, executor and world) and fig_final_error; whole or not at all."""
    from trajectotree.experiments.space_report import (
        SPACE_EXECUTION_NOTES,
        figure_final_errors,
        space_execution_markdown,
        space_execution_summary,
        space_records,
    )

    table = [space_method_summary(rows, m) for m in methods]
    records = space_records(sweep_dir, rows)
    figure = None
    with _staged(out) as stage:
        write_bytes_atomic(stage / "summary.md", (space_table_markdown(table) + SPACE_TABLE_NOTES).encode())
        write_bytes_atomic(stage / "summary.csv", table_csv(table).encode())
        if records:
            executions = space_execution_summary(records, methods)
            text = space_execution_markdown(executions, METHOD_LABELS) + SPACE_EXECUTION_NOTES
            write_bytes_atomic(stage / "executions.md", text.encode())
            write_bytes_atomic(stage / "executions.csv", table_csv(executions).encode())
            figure = _save(figure_final_errors(records, methods, METHOD_LABELS), stage / "fig_final_error")
    files = ReportFiles(
        figure_time_cost=None,
        figure_tracking=None,
        table_md=str(out / "summary.md"),
        table_csv=str(out / "summary.csv"),
        executions_md=str(out / "executions.md") if records else None,
        kind="space",
        figure_final_error=None if figure is None else tuple(str(out / Path(p).name) for p in figure),
    )
    return files, table


def _execution_report(sweep_dir: Path, rows: list[dict], methods: list[str], out: Path) -> tuple[str | None, dict]:
    """executions.md / .csv (drops and errors per method, controller and condition) and one
    Fig. 3 per controller from its nominal executions, when the sweep has executions."""
    from trajectotree.experiments.execution_report import (
        execution_markdown,
        execution_summary,
        refused_markdown,
        refused_replans,
    )
    from trajectotree.experiments.executions import collect_executions

    records = collect_executions(sweep_dir, rows)
    if not records:
        return None, {}
    table = execution_summary(records, methods)
    text = execution_markdown(table, METHOD_LABELS) + EXECUTION_NOTES
    refused = refused_replans(records)
    if refused:
        text += REFUSED_NOTES + "\n" + refused_markdown(refused, METHOD_LABELS)
    write_bytes_atomic(out / "executions.md", text.encode())
    write_bytes_atomic(out / "executions.csv", table_csv(table).encode())
    figures = {}
    for controller in sorted({r["controller"] for r in records}):
        tracks = load_execution_tracking(records, controller)
        if tracks:
            figures[controller] = _save(
                figure_tracking(tracks, methods, title=f"controller: {controller}"), out / f"fig3_tracking_{controller}"
            )
    return str(out / "executions.md"), figures


EXECUTION_NOTES = """
Each plan executed again per controller (`grasp`: object-level grasp controller, the default;
`grasp-closed-loop`: the same with the contact watch, the friction and mass estimates and the push
reflex; `grasp-replan`: that closed loop planning again from the measured state when the plan no longer
holds; `paper`: eq. 20) and condition (`nominal`: the plan's world; `mismatch`: friction 0.55 and box
mass +20 % in the simulated plant only; `push`: 0.2 N along +x on the box for 0.2 s in the middle
of the middle segment; `friction-MU`: friction MU; `mass-xF`: the box mass times F; `push-FN`: F N
along +x, timed like `push`). MAE: time means of |simulated - planned| box pose (held at its drop-time
value after a drop), then means over executions. Final error: mean |error| at the end of the run.
Replans: how often the closed loop planned again (in parentheses: how often a plan came back and took
effect); latency: wall-clock time from the replan's start to the new plan's first segment (or to the
refusal), while the hand goes on to the next node (or, from the measured state, holds), median and 95th
percentile over those replans.
"""

REFUSED_NOTES = """
## Replans without a plan

Each replan that gave no new plan, per goal: the search refused at the estimated friction (no plan,
or none within its deadline), the planner refused the start (moving, a finger off, not in closure), the new
plan's first segment failed, or the new plan was ready only after the node it starts from; the old plan went on.
"""
