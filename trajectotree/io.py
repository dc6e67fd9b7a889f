"""Saving and loading each stage's output (npz arrays + json), atomically:
every file is written to a temporary name in its folder and moved into place
with os.replace, so an interrupted run leaves no half-written file."""

from __future__ import annotations

import io as _io
import json
import os
import tempfile
from pathlib import Path

import numpy as np

SIM_JSON = "sim.json"
SIM_NPZ = "sim.npz"
SIM_ARRAYS = ("t", "x", "q", "x_plan", "abs_error", "f_W", "f_W_plan")


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_sim(result, plan_dir: str | Path) -> None:
    """plan_dir/sim.json (SimResult.to_json) and plan_dir/sim.npz (t (T,), abs_error
    (T, 3), the simulated pose x, joint angles q and planned pose x_plan, and the
    simulated and planned finger forces f_W, f_W_plan (T, 4, 2))."""
    buffer = _io.BytesIO()
    np.savez(buffer, **{name: getattr(result, name) for name in SIM_ARRAYS})
    write_bytes_atomic(Path(plan_dir) / SIM_NPZ, buffer.getvalue())
    write_bytes_atomic(Path(plan_dir) / SIM_JSON, (json.dumps(result.to_json(), indent=2) + "\n").encode())


def load_sim(plan_dir: str | Path):
    """The SimResult saved by save_sim. Raises FileNotFoundError or ValueError
    (naming the file) when sim.json / sim.npz are missing or malformed."""
    from trajectotree.simulate import SimResult
    plan_dir = Path(plan_dir)
    try:
        summary = json.loads((plan_dir / SIM_JSON).read_text())
        with np.load(plan_dir / SIM_NPZ) as data:
            arrays = {name: data[name] for name in SIM_ARRAYS}
        return SimResult(**arrays, mae_x=float(summary["mae_x"]), mae_y=float(summary["mae_y"]),
                         mae_theta=float(summary["mae_theta"]),
                         final_error=tuple(float(v) for v in summary["final_error"]),
                         dropped=bool(summary["dropped"]), drop_time_s=summary["drop_time_s"],
                         sim_time_s=float(summary["sim_time_s"]),
                         controller=summary.get("controller", "paper"),   # runs before the grasp controller
                         conditions=summary.get("conditions", {}))
    except (KeyError, TypeError, json.JSONDecodeError, OSError, ValueError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise ValueError(f"{plan_dir}: malformed {SIM_JSON} / {SIM_NPZ}: {e}") from None


PLAN_JSON = "plan.json"
PLAN_NPZ = "plan.npz"


def plan_to_json(result) -> dict:
    """plan.json (keys: README, "Trajectory optimization"): the solve report, contact sequence and config."""
    from trajectotree.config import config_to_dict
    finite = lambda v: float(v) if v is not None and np.isfinite(v) else None  # noqa: E731 (JSON has no NaN)
    return {
        "method": result.method, "goal": float(result.goal), "success": bool(result.success),
        "converged": bool(result.converged),
        "status": result.status, "search_time_s": float(result.search_time_s),
        "build_time_s": float(result.build_time_s), "solve_time_s": float(result.solve_time_s),
        "total_time_s": float(result.total_time_s), "cost": finite(result.cost), "iterations": int(result.iterations),
        "violations": {k: finite(v) for k, v in result.violations.items()},
        "physics_check": None if result.physics_check is None else result.physics_check.to_json(),
        "search": {"success": result.contact_plan.success, "reason": result.contact_plan.reason,
                   "stats": result.contact_plan.stats.to_json()},
        "contact_sequence": [n.to_json() for n in result.contact_plan.nodes],
        "solver_timing": dict(result.solver_timing),
        "config": config_to_dict(result.config),
    }


def save_plan(result, out_dir: str | Path) -> None:
    """out_dir/plan.npz (the Trajectory arrays at every knot; empty when nothing was
    solved) and out_dir/plan.json (plan_to_json), each written atomically."""
    from trajectotree.planners import TRAJECTORY_ARRAYS
    buffer = _io.BytesIO()
    arrays = {} if result.trajectory is None else {n: getattr(result.trajectory, n) for n in TRAJECTORY_ARRAYS}
    np.savez(buffer, **arrays)
    write_bytes_atomic(Path(out_dir) / PLAN_NPZ, buffer.getvalue())
    write_bytes_atomic(Path(out_dir) / PLAN_JSON, (json.dumps(plan_to_json(result), indent=2) + "\n").encode())


def load_plan(out_dir: str | Path):
    """The PlanResult saved by save_plan. Raises trajectotree.cli.InputError naming the
    file when the folder, plan.json or plan.npz is missing or malformed."""
    from trajectotree.cli import InputError
    from trajectotree.config import ConfigError, config_from_dict
    from trajectotree.contact_plan import ContactPlan
    from trajectotree.physics import PhysicsCheck
    from trajectotree.planners import TRAJECTORY_ARRAYS, PlanResult, Trajectory
    out_dir = Path(out_dir)
    json_path, npz_path = out_dir / PLAN_JSON, out_dir / PLAN_NPZ
    for path in (json_path, npz_path):
        if not path.is_file():
            raise InputError(f"{str(path)!r} is missing; a plan folder holds {PLAN_JSON} and {PLAN_NPZ} "
                             "(written by `trajectotree plan`)")
    try:
        data = json.loads(json_path.read_text())
        search = data.get("search", {})
        contact_plan = ContactPlan.from_json({"goal": data["goal"], "success": search.get("success", True),
                                              "reason": search.get("reason", ""), "stats": search.get("stats", {}),
                                              "contact_sequence": data["contact_sequence"]})
        nan = lambda v: float("nan") if v is None else float(v)  # noqa: E731
        fields = dict(method=data["method"], goal=float(data["goal"]), success=bool(data["success"]),
                      status=str(data["status"]), search_time_s=float(data["search_time_s"]),
                      build_time_s=float(data["build_time_s"]), solve_time_s=float(data["solve_time_s"]),
                      total_time_s=float(data["total_time_s"]), cost=nan(data["cost"]),
                      iterations=int(data["iterations"]), contact_plan=contact_plan,
                      violations={k: nan(v) for k, v in data["violations"].items()},
                      config=config_from_dict(data["config"]), solver_timing=data.get("solver_timing", {}))
        check = data.get("physics_check")
        fields["physics_check"] = None if check is None else PhysicsCheck.from_json(check)
        fields["converged"] = bool(data.get("converged", data["success"]))   # older files: success meant converged
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        if isinstance(e, ConfigError):
            raise InputError(f"{str(json_path)!r} holds an invalid config: {e}") from None
        raise InputError(f"{str(json_path)!r} is not a valid plan.json ({type(e).__name__}: {e})") from None
    try:
        with np.load(npz_path) as npz:
            arrays = {name: np.array(npz[name]) for name in npz.files}
    except (OSError, ValueError, EOFError) as e:
        raise InputError(f"{str(npz_path)!r} is not a valid plan.npz: {e}") from None
    trajectory = None
    if arrays:
        missing = [n for n in TRAJECTORY_ARRAYS if n not in arrays]
        if missing:
            raise InputError(f"{str(npz_path)!r} lacks the arrays {missing}"
                             + (" (written before plan.npz had p_W_C; plan it again)" if missing == ["p_W_C"] else ""))
        trajectory = Trajectory(**{n: arrays[n] for n in TRAJECTORY_ARRAYS})
    return PlanResult(**fields, trajectory=trajectory)
