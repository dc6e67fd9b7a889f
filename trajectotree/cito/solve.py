"""IPOPT on a CitoProgram: options, the solve, and the per-group violation report.

Options, as measured on these programs: SPRAL with metis ordering, no scaling and
nemin 4 (SPRAL's defaults redo the analysis every iteration), L-BFGS (Drake
passes no Hessian), and every tolerance set explicitly (Drake's default is 1e-10).
IPOPT writes its summary to a temporary file, from which the iteration count and
its time split (function evaluations vs IPOPT's own) are read. Tried on the 27 first-round
segments of three goals and left off (issue 35): mu_init 1e-2 or 1e-3, smaller bound_push and
bound_frac, and warm_start_init_point (5 % more iterations: the guess has no multipliers).
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field

import numpy as np
from pydrake.solvers import IpoptSolver, SolverOptions

from trajectotree.cito.program import CitoProgram
from trajectotree.cito.variables import CitoVariables
from trajectotree.config import CitoConfig

VIOLATION_GROUPS = ("dynamics", "friction_cone", "complementarity", "contact_point", "penetration")


@dataclass(frozen=True)
class SolveOutcome:
    success: bool
    status: str  # IPOPT's return status name
    iterations: int  # -1 when IPOPT's summary could not be read
    cost: float
    solution: CitoVariables
    solve_time_s: float
    timing: dict = field(default_factory=dict)  # IPOPT's timing statistics (s), when printed


def ipopt_options(config: CitoConfig, output_file: str | None = None, timing_statistics: bool = False) -> SolverOptions:
    options = SolverOptions()
    settings = {
        "linear_solver": "spral",
        "spral_order": "metis",
        "spral_scaling": "none",
        "spral_nemin": 4,
        "hessian_approximation": "limited-memory",
        "limited_memory_max_history": config.lbfgs_history,
        "tol": config.tol,
        "constr_viol_tol": config.constr_viol_tol,
        "acceptable_tol": config.acceptable_tol,
        "acceptable_constr_viol_tol": config.acceptable_constr_viol_tol,
        "acceptable_iter": config.acceptable_iter,
        "max_iter": config.max_iter,
        "print_level": config.print_level,
    }
    if output_file:
        # The summary's totals (IPOPT's own time and the function evaluations') come without the
        # timing statistics, whose per-component timers cost ~4 % of the solve (issue 35).
        statistics = "yes" if timing_statistics else "no"
        settings.update(output_file=output_file, file_print_level=3, print_timing_statistics=statistics)
    for name, value in settings.items():
        options.SetOption(IpoptSolver.id(), name, value)
    return options


# Watches a solve, e.g. a progress display (trajectotree.cli.progress): called with the path of
# IPOPT's log, it returns a context manager that is active while IPOPT runs.
LogObserver = Callable[[str], AbstractContextManager]


def solve(
    program: CitoProgram,
    guess: CitoVariables,
    config: CitoConfig,
    log_observer: LogObserver | None = None,
    max_wall_time_s: float | None = None,
    timing_statistics: bool = False,
) -> SolveOutcome:
    """IPOPT from `guess`; with a `log_observer` the log also holds IPOPT's iteration lines
    (file_print_level 5) while it runs, and the solve itself is unchanged. `max_wall_time_s` stops
    IPOPT after that long (IPOPT's max_wall_time; unsuccessful then), for a solve with a deadline.
    `timing_statistics` adds IPOPT's per-component times (the linear solver's) to the outcome's timing."""
    prog, v = program.prog, program.variables
    v.set_initial_guess(prog, guess)
    fd, log_path = tempfile.mkstemp(prefix="trajectotree_ipopt_", suffix=".txt")
    os.close(fd)
    try:
        options = ipopt_options(config, log_path, timing_statistics)
        if log_observer is not None:
            options.SetOption(IpoptSolver.id(), "file_print_level", 5)
        if max_wall_time_s is not None:
            options.SetOption(IpoptSolver.id(), "max_wall_time", max(float(max_wall_time_s), 1e-3))
        with log_observer(log_path) if log_observer is not None else contextlib.nullcontext():
            t0 = time.perf_counter()
            result = IpoptSolver().Solve(prog, None, options)
            solve_time = time.perf_counter() - t0
        summary = _read(log_path)
    finally:
        os.unlink(log_path)
    details = result.get_solver_details()
    status = details.ConvertStatusToString()
    return SolveOutcome(
        success=bool(result.is_success()),
        status=status,
        iterations=_iterations(summary),
        cost=float(result.get_optimal_cost()),
        solution=v.eval_result(result),
        solve_time_s=solve_time,
        timing=_timing(summary),
    )


def _read(path: str) -> str:
    try:
        with open(path) as f:
            return f.read()
    except OSError:
        return ""


def _iterations(summary: str) -> int:
    m = re.search(r"Number of Iterations\.*:\s*(\d+)", summary)
    return int(m.group(1)) if m else -1


def _timing(summary: str) -> dict:
    """Seconds from IPOPT's timing statistics: total, in function evaluations, own, and of
    its own the linear solver's factorizations and back-solves; without them, the total alone."""
    out = {}
    for key, pattern in (
        ("ipopt_total_s", r"OverallAlgorithm\.*:\s*([\d.]+)"),
        ("function_evaluations_s", r"Function Evaluations\.*:\s*([\d.]+)"),
        ("linear_system_factorization_s", r"LinearSystemFactorization\.*:\s*([\d.]+)"),
        ("linear_system_back_solve_s", r"LinearSystemBackSolve\.*:\s*([\d.]+)"),
        ("ipopt_without_function_evaluations_s", r"Total seconds in IPOPT \(w/o function evaluations\)\s*=\s*([\d.]+)"),
        ("nlp_function_evaluations_s", r"Total seconds in NLP function evaluations\s*=\s*([\d.]+)"),
        ("ipopt_total_s", r"Total seconds in IPOPT\s*=\s*([\d.]+)"),  # the summary's, without the statistics
    ):
        m = re.search(pattern, summary)
        if m and key not in out:
            out[key] = float(m.group(1))
    return out


def violations(program: CitoProgram, sol: CitoVariables, scene) -> dict:
    """Max absolute violation per constraint group, physical (without the slacks):
    dynamics (object and hand rows, collocation), friction_cone, complementarity
    (phi lambda_n and |v_rel| lambda_n of free fingers), contact_point (distance of
    pinned fingertips from their planned points) and penetration (exact distance)."""
    rows, dt = program.rows, program.spec.dt
    Z = sol.stacked()
    val, _ = rows.evaluate(Z, False)
    kin = rows.kinematics(Z)
    col = [
        np.abs(np.diff(a, axis=0) - 0.5 * dt * (b[1:] + b[:-1])).max()
        for a, b in ((sol.x, sol.xd), (sol.xd, sol.xdd), (sol.q, sol.qd), (sol.qd, sol.qdd))
    ]
    mu = rows.body.mu  # the planning friction mu_plan the cones were built with
    ln, lt = sol.lambda_n, sol.lambda_t
    free = ~rows.pinned
    comp = np.maximum(np.abs(kin.phi_tip) * ln, np.linalg.norm(kin.v, axis=-1) * ln)
    boundary = scene.config.shape
    exact = np.array([[boundary.signed_distance(p) for p in knot] for knot in kin.p_BF]) - rows.body.radius
    return {
        "dynamics": float(max(np.abs(val[:, : rows.layout.num_body_rows]).max(), *col)),
        "friction_cone": float(max(0.0, (np.abs(lt) - mu * ln).max(), (-ln).max())),
        "complementarity": float(comp[free].max()) if free.any() else 0.0,
        "contact_point": float(np.linalg.norm(kin.e, axis=-1)[rows.pinned].max()) if rows.pinned.any() else 0.0,
        "penetration": float(max(0.0, -exact.min())),
    }
