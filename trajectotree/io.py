"""Saving and loading each stage's output (npz arrays + json), atomically:
every file is written to a temporary name in its folder and moved into place
with os.replace, so an interrupted run leaves no half-written file.

A leaf over plain values: it reads and writes the types of trajectotree.results
(and the config and contact plan they hold) and imports no stage that makes them.
Bad or missing files raise trajectotree.config.ConfigError naming the file.
"""

from __future__ import annotations

import io as _io
import json
import os
import tempfile
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trajectotree.config import Config, ConfigError, config_from_dict, config_to_dict
from trajectotree.contact_plan import ContactPlan
from trajectotree.results import (
    CLOSED_LOOP_ARRAYS,
    SIM_ARRAYS,
    TRAJECTORY_ARRAYS,
    ClosedLoopLog,
    PhysicsCheck,
    PlanResult,
    SimResult,
    Trajectory,
)
from trajectotree.start import StartState

SIM_JSON = "sim.json"
SIM_NPZ = "sim.npz"
PLAN_JSON = "plan.json"
PLAN_NPZ = "plan.npz"


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


def npz_problem(path: str | Path) -> str | None:
    """Why the .npz file at `path` cannot be read whole (missing, truncated, a corrupt
    member), or None when every array in it reads back (zip CRCs checked)."""
    try:
        with np.load(path) as data:
            for name in data.files:
                data[name]
    except (OSError, ValueError, KeyError, EOFError, TypeError, AttributeError, zipfile.BadZipFile) as e:
        return f"{type(e).__name__}: {e}"  # TypeError, AttributeError: an .npy or pickle, not an archive
    return None


def write_json_atomic(path: str | Path, data: dict) -> None:
    """`data` as indented JSON with a final newline (every json file of a run)."""
    write_bytes_atomic(path, (json.dumps(data, indent=2) + "\n").encode())


def _npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    buffer = _io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def save_sim(result: SimResult, plan_dir: str | Path) -> None:
    """plan_dir/sim.json (SimResult.to_json) and plan_dir/sim.npz (t (T,), abs_error
    (T, 3), the simulated pose x, joint angles q and planned pose x_plan, and the
    simulated and planned finger forces f_W, f_W_plan (T, 4, 2)), and of a closed-loop run
    the ClosedLoopLog's arrays too (results.CLOSED_LOOP_ARRAYS)."""
    arrays = {name: getattr(result, name) for name in SIM_ARRAYS}
    if result.closed_loop is not None:
        arrays |= result.closed_loop.arrays()
    write_bytes_atomic(Path(plan_dir) / SIM_NPZ, _npz_bytes(arrays))
    write_json_atomic(Path(plan_dir) / SIM_JSON, result.to_json())


def load_sim(plan_dir: str | Path) -> SimResult:
    """The SimResult saved by save_sim. ConfigError naming the file when sim.json or
    sim.npz is missing or malformed."""
    json_path, npz_path = Path(plan_dir) / SIM_JSON, Path(plan_dir) / SIM_NPZ
    require_files(
        (json_path, npz_path), f"a run's folder holds {SIM_JSON} and {SIM_NPZ} (written by `trajectotree simulate`)"
    )
    with reading(json_path):
        summary = json.loads(json_path.read_text())
        values = dict(
            mae_x=float(summary["mae_x"]),
            mae_y=float(summary["mae_y"]),
            mae_theta=float(summary["mae_theta"]),
            final_error=tuple(float(v) for v in summary["final_error"]),
            dropped=bool(summary["dropped"]),
            drop_time_s=summary["drop_time_s"],
            error_at_drop=None if summary.get("error_at_drop") is None else tuple(summary["error_at_drop"]),
            diverged_at_s=summary.get("diverged_at_s"),  # runs before the divergence test: none
            divergence=summary.get("divergence"),
            sim_time_s=float(summary["sim_time_s"]),
            controller=summary.get("controller", "paper"),  # runs before the grasp controller
            conditions=summary.get("conditions", {}),
        )
    with reading(npz_path), np.load(npz_path) as data:
        arrays = {name: data[name] for name in SIM_ARRAYS}
        closed_loop = None
        if CLOSED_LOOP_ARRAYS[0] in data:  # a closed-loop run
            closed_loop = ClosedLoopLog(**{name: data[name] for name in CLOSED_LOOP_ARRAYS})
    return SimResult(**arrays, **values, closed_loop=closed_loop)


def plan_to_json(result: PlanResult) -> dict:
    """plan.json (keys: README, "Trajectory optimization"): the solve report, contact sequence and config."""

    def finite(v) -> float | None:  # JSON has no NaN
        return float(v) if v is not None and np.isfinite(v) else None

    return {
        "method": result.method,
        "goal": float(result.goal),
        "goal_position": None if result.contact_plan.goal_position is None else list(result.contact_plan.goal_position),
        "success": bool(result.success),
        "converged": bool(result.converged),
        "status": result.status,
        "search_time_s": float(result.search_time_s),
        "build_time_s": float(result.build_time_s),
        "solve_time_s": float(result.solve_time_s),
        "total_time_s": float(result.total_time_s),
        "cost": finite(result.cost),
        "iterations": int(result.iterations),
        "violations": {k: finite(v) for k, v in result.violations.items()},
        "physics_check": None if result.physics_check is None else result.physics_check.to_json(),
        "search": {
            "success": result.contact_plan.success,
            "reason": result.contact_plan.reason,
            "refusal": None if result.contact_plan.refusal is None else result.contact_plan.refusal.to_json(),
            "stats": result.contact_plan.stats.to_json(),
            "mu_plan": finite(result.contact_plan.mu_plan),
        },
        "contact_sequence": [n.to_json() for n in result.contact_plan.nodes],
        "solver_timing": dict(result.solver_timing),
        "formulation": result.formulation,
        "segments": list(result.segments),
        "config": config_to_dict(result.config),
    }


def save_plan(result: PlanResult, out_dir: str | Path) -> None:
    """out_dir/plan.npz (the Trajectory arrays at every knot; empty when nothing was
    solved) and out_dir/plan.json (plan_to_json), each written atomically."""
    arrays = {} if result.trajectory is None else result.trajectory.arrays()
    write_bytes_atomic(Path(out_dir) / PLAN_NPZ, _npz_bytes(arrays))
    write_json_atomic(Path(out_dir) / PLAN_JSON, plan_to_json(result))


@dataclass(frozen=True)
class PlanFiles:
    """A plan folder as read: plan.json's data, its Config and the plan.npz arrays."""

    folder: Path
    data: dict  # plan.json as parsed
    config: Config  # plan.json's config
    arrays: dict[str, np.ndarray]  # every TRAJECTORY_ARRAYS name, or none when planning solved nothing

    @property
    def json_path(self) -> Path:
        return self.folder / PLAN_JSON

    @property
    def npz_path(self) -> Path:
        return self.folder / PLAN_NPZ


@contextmanager
def reading(path: Path):
    """Turns an error met while parsing `path` into a ConfigError naming the file."""
    try:
        yield
    except ConfigError as e:  # only config_from_dict raises it while a plan is read
        raise ConfigError(f"{str(path)!r} holds an invalid config: {e}") from None
    except (KeyError, TypeError, ValueError, AttributeError, OSError, EOFError, zipfile.BadZipFile) as e:
        # JSONDecodeError and UnicodeDecodeError are ValueErrors; a truncated zip is a BadZipFile
        raise ConfigError(f"{str(path)!r} is not a valid {path.name} ({type(e).__name__}: {e})") from None


def require_files(paths, holds: str) -> None:
    """ConfigError naming the first of `paths` that is not a file; `holds` says what should be there."""
    for path in paths:
        if not Path(path).is_file():
            raise ConfigError(f"{str(path)!r} is missing; {holds}")


def read_plan_files(folder: str | Path, name: str = "plan folder") -> PlanFiles:
    """The plan folder written by save_plan (`name` says what it is to the user, e.g. a
    command's argument). ConfigError naming the folder or file when the folder or a file is
    missing, a file is malformed, the config invalid or a trajectory array missing."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigError(f"{name} {str(folder)!r} is not a directory")
    json_path, npz_path = folder / PLAN_JSON, folder / PLAN_NPZ
    require_files(
        (json_path, npz_path), f"a plan folder holds {PLAN_JSON} and {PLAN_NPZ} (written by `trajectotree plan`)"
    )
    with reading(json_path):
        data = json.loads(json_path.read_text())
        config = config_from_dict(data["config"])
    with reading(npz_path), np.load(npz_path) as npz:
        arrays = {key: np.array(npz[key]) for key in npz.files}
    missing = [n for n in TRAJECTORY_ARRAYS if n not in arrays]
    if arrays and missing:
        raise ConfigError(
            f"{str(npz_path)!r} lacks the arrays {missing}"
            + (" (written before plan.npz had p_W_C; plan it again)" if missing == ["p_W_C"] else "")
        )
    return PlanFiles(folder=folder, data=data, config=config, arrays=arrays)


def load_plan(out_dir: str | Path) -> PlanResult:
    """The PlanResult saved by save_plan (trajectory None when nothing was solved).
    Raises ConfigError naming the folder or file when missing or malformed (read_plan_files)."""
    files = read_plan_files(out_dir)
    with reading(files.json_path):
        data = files.data
        search = data.get("search", {})
        contact_plan = ContactPlan.from_json(
            {
                "goal": data["goal"],
                "goal_position": data.get("goal_position"),  # older files: rotations only
                "success": search.get("success", True),
                "reason": search.get("reason", ""),
                "refusal": search.get("refusal"),  # older files have the reason's text alone
                "stats": search.get("stats", {}),
                "mu_plan": search.get("mu_plan"),  # older files lack it
                "contact_sequence": data["contact_sequence"],
            }
        )

        def nan(v) -> float:
            return float("nan") if v is None else float(v)

        check = data.get("physics_check")
        result = PlanResult(
            method=data["method"],
            goal=float(data["goal"]),
            success=bool(data["success"]),
            status=str(data["status"]),
            search_time_s=float(data["search_time_s"]),
            build_time_s=float(data["build_time_s"]),
            solve_time_s=float(data["solve_time_s"]),
            total_time_s=float(data["total_time_s"]),
            cost=nan(data["cost"]),
            iterations=int(data["iterations"]),
            contact_plan=contact_plan,
            violations={k: nan(v) for k, v in data["violations"].items()},
            config=files.config,
            solver_timing=data.get("solver_timing", {}),
            physics_check=None if check is None else PhysicsCheck.from_json(check),
            converged=bool(data.get("converged", data["success"])),  # older files: success meant converged
            formulation=str(data.get("formulation", "joint")),
            segments=tuple(data.get("segments", ())),
            trajectory=Trajectory(**{n: files.arrays[n] for n in TRAJECTORY_ARRAYS}) if files.arrays else None,
        )
    return result


def save_start(start: StartState, path: str | Path) -> None:
    """start.json: a StartState (trajectotree.start), written atomically."""
    write_json_atomic(path, start.to_json())


def load_start(path: str | Path) -> StartState:
    """A start state from its JSON file; ConfigError naming the file when it cannot be read as one."""
    path = Path(path)
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"--start {str(path)!r}: no such file") from None
    except IsADirectoryError:
        raise ConfigError(f"--start {str(path)!r} is a folder; give a start.json file") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError(f"--start {str(path)!r} is not a JSON start state ({e})") from None
    return StartState.from_json(data, where=f"--start {str(path)!r}")
