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
SIM_ARRAYS = ("t", "x", "q", "x_plan", "abs_error")


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
    (T, 3), and the simulated pose x, joint angles q and planned pose x_plan)."""
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
                         sim_time_s=float(summary["sim_time_s"]))
    except (KeyError, TypeError, json.JSONDecodeError, OSError, ValueError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise ValueError(f"{plan_dir}: malformed {SIM_JSON} / {SIM_NPZ}: {e}") from None
