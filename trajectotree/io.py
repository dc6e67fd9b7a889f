"""Saving and loading each stage's output (npz arrays + json), atomically:
every file is written to a temporary name in its folder and moved into place
with os.replace, so an interrupted run leaves no half-written file. A plan's two
files are a pair: plan.json records the SHA-256 of plan.npz's arrays, and its
values' JSON types are checked on load. `folder_lock` keeps one command at a time
writing into a folder; `check_output_file` checks where an output file goes.

A leaf over plain values: it reads and writes the types of trajectotree.results
(and the config and contact plan they hold) and imports no stage that makes them.
Bad or missing files raise trajectotree.config.ConfigError naming the file.
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import io as _io
import json
import os
import socket
import sys
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trajectotree.config import Config, ConfigError, config_from_dict, config_to_dict, is_file
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
from trajectotree.start import SpaceStartState, StartState

SIM_JSON = "sim.json"
SIM_NPZ = "sim.npz"
PLAN_JSON = "plan.json"
PLAN_NPZ = "plan.npz"
LOCK_FILE = ".lock"
HTML_SUFFIXES = (".html", ".htm")  # a Meshcat playback's file names
GIF_SUFFIXES = (".gif",)
# plan.json's key for the SHA-256 of plan.npz's arrays (arrays_digest): what makes the two files a pair.
ARRAYS_DIGEST = "arrays_sha256"


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
    summary = read_json_object(json_path, SIM_JSON_TYPES)
    with reading(json_path):
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
        ARRAYS_DIGEST: arrays_digest({} if result.trajectory is None else result.trajectory.arrays()),
        "config": config_to_dict(result.config),
    }


def arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    """The SHA-256 of named arrays (each name, dtype, shape and C-order bytes, names sorted):
    the same arrays give the same digest however the .npz holding them was zipped."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def save_plan(result: PlanResult, out_dir: str | Path) -> None:
    """out_dir/plan.npz (the Trajectory arrays at every knot; empty when nothing was
    solved) and out_dir/plan.json (plan_to_json, with the arrays' digest that pairs the two
    files), each written atomically."""
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
    # None when plan.json's arrays digest matched plan.npz; else what was checked of an older pair without one
    unverified: str | None = None

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
        if not is_file(path):
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
    data = read_json_object(json_path, PLAN_JSON_TYPES)
    with reading(json_path):
        config = config_from_dict(data["config"])
    with reading(npz_path), np.load(npz_path) as npz:
        arrays = {key: np.array(npz[key]) for key in npz.files}
    missing = [n for n in TRAJECTORY_ARRAYS if n not in arrays]
    if arrays and missing:
        raise ConfigError(
            f"{str(npz_path)!r} lacks the arrays {missing}"
            + (" (written before plan.npz had p_W_C; plan it again)" if missing == ["p_W_C"] else "")
        )
    files = PlanFiles(folder=folder, data=data, config=config, arrays=arrays)
    return dataclasses.replace(files, unverified=check_plan_pair(files))


def check_plan_pair(files: PlanFiles) -> str | None:
    """ConfigError naming both files and what differs when plan.npz is not the arrays plan.json
    was saved with (the files of two plans side by side): the arrays' digest plan.json records, and
    what plan.json says of them (knots per node, joints per knot, the final orientation of a
    successful plan). None when the digest matched; for an older plan.json without one, a note that
    only the rest was checked."""
    where = f"{str(files.npz_path)!r} does not belong to the plan {str(files.json_path)!r} describes"
    recorded = files.data.get(ARRAYS_DIGEST)
    if recorded is not None and recorded != arrays_digest(files.arrays):
        raise ConfigError(
            f"{where}: the SHA-256 of its arrays is {arrays_digest(files.arrays)[:12]}..., plan.json records "
            f"{recorded[:12]}... ({PLAN_NPZ}: {_arrays_summary(files.arrays)}; {PLAN_JSON}: "
            f"{_plan_summary(files.data)}); put the plan.json and plan.npz of one plan together, or plan again"
        )
    problem = _pair_mismatch(files, goal_too=recorded is None)
    if problem:
        raise ConfigError(f"{where}: {problem}")
    if recorded is None and files.arrays:
        return (
            f"{str(files.json_path)!r} records no {ARRAYS_DIGEST} (saved before plans did), so only that "
            f"{PLAN_NPZ}'s knots, joints and final orientation fit it was checked"
        )
    return None


# rad, how far a successful keyframes plan's last knot may end from its goal's orientation: its last
# segment's end knot is fixed at the goal node (to IPOPT's constraint tolerance, 1e-6), while the other
# plan of a pair mixed up ends elsewhere by far more. (The joint program only tracks its goals in its cost.)
GOAL_FIT_TOL = 1e-3


def _pair_mismatch(files: PlanFiles, goal_too: bool) -> str | None:
    """What plan.json says that plan.npz's arrays contradict, or None; `goal_too`: also whether a
    successful plan of TrajectoTree's keyframes formulation ends at its goal (GOAL_FIT_TOL)."""
    arrays, data = files.arrays, files.data
    if not arrays:
        return None
    knots = {name: len(a) for name, a in arrays.items() if a.ndim}
    if len(set(knots.values())) > 1:
        return f"its arrays have different numbers of knots ({knots})"
    nodes = data.get("contact_sequence") or ()
    M, K = files.config.cito.knots_per_segment, next(iter(knots.values()), 0)
    if data.get("method") == "trajectotree" and len(nodes) >= 2 and K != (len(nodes) - 1) * M + 1:
        return (
            f"it has {K} knots, plan.json's {len(nodes)} nodes of cito.knots_per_segment {M} "
            f"make {(len(nodes) - 1) * M + 1}"
        )
    joints = len(nodes[0].get("q") or ()) if nodes and isinstance(nodes[0], dict) else None
    if joints and arrays["q"].ndim == 2 and arrays["q"].shape[1] != joints:
        return f"its q has {arrays['q'].shape[1]} joint angles per knot, plan.json's nodes {joints}"
    goal, theta = data.get("goal"), _final_theta(arrays)
    successful = (
        data.get("formulation") == "keyframes" and data.get("method") == "trajectotree" and data.get("success") is True
    )
    if goal_too and successful and goal is not None and theta is not None and abs(theta - goal) > GOAL_FIT_TOL:
        return (
            f"it ends at orientation {theta:+.4f} rad, {abs(theta - goal):.4f} rad from plan.json's goal "
            f"{goal:+.4f} rad (a successful plan ends within {GOAL_FIT_TOL:g} rad of its goal)"
        )
    return None


def _final_theta(arrays: dict[str, np.ndarray]) -> float | None:
    """rad, the object's orientation at the last knot (x is (K, 3)), or None when x has no such entry."""
    x = arrays.get("x")
    return float(x[-1, 2]) if x is not None and x.ndim == 2 and len(x) and x.shape[1] == 3 else None


def _arrays_summary(arrays: dict[str, np.ndarray]) -> str:
    theta = _final_theta(arrays)
    if not arrays or theta is None:
        return "no trajectory"
    return f"{len(arrays['x'])} knots, ending at orientation {theta:+.4f} rad"


def _plan_summary(data: dict) -> str:
    goal = data.get("goal")
    nodes = len(data.get("contact_sequence") or ())
    return ("no goal" if goal is None else f"goal {goal:+.4f} rad") + f", {nodes} nodes"


# The JSON types of each kind a plan.json or sim.json value may have, in the order a value is named by.
JSON_KINDS = {
    "a JSON boolean (true or false)": lambda v: isinstance(v, bool),
    "an integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "a number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "a string": lambda v: isinstance(v, str),
    "null": lambda v: v is None,
    "an object": lambda v: isinstance(v, dict),
    "a list": lambda v: isinstance(v, list),
}
BOOLEAN, INTEGER, NUMBER, STRING, NULL, OBJECT, LIST = JSON_KINDS
# plan.json's keys (plan_to_json) and the kinds of their values; a nested dict: an object's keys.
# Older files lack some keys: only the keys present are checked.
PLAN_JSON_TYPES = {
    "method": (STRING,),
    "goal": (NUMBER,),
    "goal_position": (LIST, NULL),
    "success": (BOOLEAN,),
    "converged": (BOOLEAN,),
    "status": (STRING,),
    "search_time_s": (NUMBER,),
    "build_time_s": (NUMBER,),
    "solve_time_s": (NUMBER,),
    "total_time_s": (NUMBER,),
    "cost": (NUMBER, NULL),
    "iterations": (INTEGER,),
    "violations": (OBJECT,),
    "physics_check": (OBJECT, NULL),
    "search": {"success": (BOOLEAN,), "reason": (STRING,), "refusal": (OBJECT, NULL), "stats": (OBJECT,)},
    "contact_sequence": (LIST,),
    "solver_timing": (OBJECT,),
    "formulation": (STRING,),
    "segments": (LIST,),
    ARRAYS_DIGEST: (STRING,),
    "config": (OBJECT,),
}
# sim.json's keys that load_sim reads.
SIM_JSON_TYPES = {
    "mae_x": (NUMBER,),
    "mae_y": (NUMBER,),
    "mae_theta": (NUMBER,),
    "final_error": (LIST,),
    "dropped": (BOOLEAN,),
    "drop_time_s": (NUMBER, NULL),
    "error_at_drop": (LIST, NULL),
    "sim_time_s": (NUMBER,),
    "controller": (STRING,),
    "conditions": (OBJECT,),
}


def read_json_object(path: Path, types: dict) -> dict:
    """The JSON object in `path`, its values' kinds checked (check_json_types); ConfigError naming
    the file when it is no JSON object."""
    with reading(path):
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise ValueError(f"a JSON object was expected, not {_json_kind(data)}")
    check_json_types(data, types, path)
    return data


def _json_kind(value) -> str:
    return next((kind for kind, test in JSON_KINDS.items() if test(value)), type(value).__name__)


def check_json_types(data: dict, types: dict, path: Path, prefix: str = "") -> None:
    """ConfigError naming the file, the key, its value and the kinds it may be, for the first key
    of `types` present in `data` whose value is of none of them (e.g. "success": "yes")."""
    for key, kinds in types.items():
        if key not in data:
            continue
        value, name = data[key], f"{prefix}{key}"
        if isinstance(kinds, dict):
            if not isinstance(value, dict):
                kinds = (OBJECT,)
            else:
                check_json_types(value, kinds, path, f"{name}.")
                continue
        if not any(JSON_KINDS[kind](value) for kind in kinds):
            raise ConfigError(
                f"{str(path)!r}: {name} = {json.dumps(value)} is {_json_kind(value)}; it must be {' or '.join(kinds)}"
            )


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


def load_start(path: str | Path, name: str = "--start", *, space: bool = False) -> StartState | SpaceStartState:
    """A start state from its JSON file (`space`: a hand in space's, SpaceStartState); ConfigError naming the
    file (after `name`, e.g. the option that gave it) when it cannot be read as one."""
    path = Path(path)
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{name} {str(path)!r}: no such file") from None
    except IsADirectoryError:
        raise ConfigError(f"{name} {str(path)!r} is a folder; give a start.json file") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError(f"{name} {str(path)!r} is not a JSON start state ({e})") from None
    kind = SpaceStartState if space else StartState
    return kind.from_json(data, where=f"{name} {str(path)!r}")


def cannot_create_in(folder: Path) -> str | None:
    """Why no file can be created in `folder`, or None when one can: a probe file is made
    and removed at once. Permission bits (and os.access) do not tell: root ignores them,
    and they know nothing of an immutable folder or a read-only bind mount."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".trajectotree-probe-")
    except OSError as e:
        return e.strerror or type(e).__name__
    os.close(fd)
    os.unlink(probe)
    return None


def _path_limit(folder: Path, name: str, default: int) -> int:
    """os.pathconf(folder, name), or `default` (Linux's) where the system does not say."""
    try:
        return os.pathconf(folder, name)
    except (OSError, ValueError):
        return default


def check_name_lengths(option: str, path: str | Path, files: tuple[str, ...] = ()) -> None:
    """ConfigError (exit 2, before any work) when a name in `path` is longer than its file system
    allows (NAME_MAX bytes, of the deepest existing folder on the way: new folders go there) or
    the whole path, with the longest of `files` written into it, is (PATH_MAX bytes, with the
    terminating NUL); without it the first stat of the path fails with an OSError."""
    absolute = Path(os.path.abspath(path))
    written = absolute / max(files, key=len) if files else absolute
    path_max = _path_limit(Path(absolute.anchor), "PC_PATH_MAX", 4096)
    if len(os.fsencode(str(written))) >= path_max:
        with_file = f" with the file {written.name} in it" if files else ""
        raise ConfigError(
            f"{option} {str(path)!r} is too long: {len(os.fsencode(str(written)))} bytes as an absolute path"
            f"{with_file}; valid: at most {path_max - 1} bytes (PATH_MAX)"
        )
    folder = Path(absolute.anchor)
    for name in absolute.parts[1:]:
        name_max = _path_limit(folder, "PC_NAME_MAX", 255)
        if len(os.fsencode(name)) > name_max:
            raise ConfigError(
                f"{option} {str(path)!r}: a name in it is {len(os.fsencode(name))} bytes long; valid: at most "
                f"{name_max} bytes per name (NAME_MAX of {str(folder)!r})"
            )
        if (folder / name).is_dir():
            folder = folder / name


def check_output_file(
    option: str, path: str | Path, suffixes: tuple[str, ...], *, created: tuple[Path, ...] = ()
) -> Path:
    """An output file: its name ends in one of `suffixes`, it is not a folder, and it goes
    into an existing folder in which files can be created, or into one of the `created`
    output folders (the command makes them; check_output_dir checks them). Checked before any
    work starts (ConfigError: exit 2), by the CLI and the API (run_simulation's html_path) alike."""
    check_name_lengths(option, path)
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ConfigError(f"{option} {str(path)!r}: the file name must end in {' or '.join(suffixes)}")
    if path.is_dir():
        raise ConfigError(f"{option} {str(path)!r} is a folder; give a file name ending in {' or '.join(suffixes)}")
    folder = Path(os.path.abspath(path)).parent
    if not folder.exists() and any(folder == Path(os.path.abspath(c)) for c in created):
        return path  # written after the command has created that folder
    if not folder.is_dir():
        raise ConfigError(f"{option} {str(path)!r}: the folder {str(path.parent)!r} does not exist")
    why = cannot_create_in(folder)
    if why:
        raise ConfigError(
            f"{option} {str(path)!r} cannot be written: no file can be created in {str(path.parent)!r} ({why})"
        )
    return path


@contextmanager
def folder_lock(
    folder: str | Path, name: str, holder: str, *, create: bool = True, keep: bool = False
) -> Iterator[Path]:
    """Holds FOLDER/.lock (flock, not waiting; the kernel releases it if this process dies) while
    `holder` (what another command is told holds it: "sweep", "trajectotree plan") works in the
    folder; ConfigError naming `name`, the folder and the holder's pid when another process holds
    it. The file holds the holder's pid and name while held, so a pid found on taking it belonged to
    a process that died: its stale lock is taken over, with a note on stderr. `keep`: the file stays,
    emptied, on release (a sweep's folder keeps it); otherwise it is removed, and so are the folders
    this lock created when nothing else was written into them. `create` False: the folder must exist."""
    folder = Path(folder)
    made = _make_folders(folder, name) if create else []
    try:
        if not folder.is_dir():
            raise ConfigError(f"{name} {str(folder)!r} is not a directory")
        fd, previous = _take_lock(folder, name)
        try:
            if previous:
                print(
                    f"{holder} {folder}: taking over the stale lock of process {previous}, which is gone",
                    file=sys.stderr,
                )
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n{holder}\n".encode(), 0)
            yield folder
        finally:
            if keep:
                os.ftruncate(fd, 0)
            else:  # unlinked while held: a process waiting on this file finds it gone and makes a new one
                (folder / LOCK_FILE).unlink(missing_ok=True)
            os.close(fd)
    finally:
        for path in made:  # the deepest first; one that holds anything stays, and so do its parents
            try:
                path.rmdir()
            except OSError:
                break


def _make_folders(folder: Path, name: str) -> list[Path]:
    """Creates `folder` and its missing parents; returns those it created, the deepest first."""
    missing, path = [], folder.absolute()
    while not path.exists() and path != path.parent:
        missing.append(path)
        path = path.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ConfigError(f"{name} {str(folder)!r} is an existing file, not a folder") from None
    except OSError as e:
        raise ConfigError(f"{name} {str(folder)!r} cannot be created ({e.strerror})") from None
    return missing


def _take_lock(folder: Path, name: str) -> tuple[int, str]:
    """An open descriptor of folder/.lock, locked, and the pid line a dead holder left in it ("" if none)."""
    path = folder / LOCK_FILE
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise ConfigError(
                f"{name} {str(folder)!r} cannot be written: no file can be created in {str(folder)!r} ({e.strerror})"
            ) from None
        try:
            recorded = os.pread(fd, 256, 0).decode(errors="replace").splitlines() + ["", ""]
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise ConfigError(
                    f"{name} {str(folder)!r} is in use by another {recorded[1] or 'trajectotree command'} (process "
                    f"{recorded[0] or 'unknown pid'}; lock file {str(path)!r}); wait for it to finish or stop it, "
                    f"or choose another {name}"
                ) from None
            if _still_at(fd, path):
                return fd, recorded[0]
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)  # its holder removed it on release before this process locked it: take the new one


def _still_at(fd: int, path: Path) -> bool:
    """Whether the open file `fd` is still the file at `path`."""
    try:
        on_disk = os.stat(path)
    except FileNotFoundError:
        return False
    mine = os.fstat(fd)
    return (mine.st_dev, mine.st_ino) == (on_disk.st_dev, on_disk.st_ino)
