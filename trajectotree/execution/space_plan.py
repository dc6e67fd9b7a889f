"""A plan in space's folder (plan.json `kind: space` and plan.npz, planning.spatial.save_space_plan) read for
execution and a run of it written beside it: `read_space_plan` (the two files, their arrays' shapes checked),
`check_arrays_fit_scene` (the arrays belong to the cube plan.json names), `load_space_plan` (all that a run needs:
`SpacePlan`) and `save_space_sim` (sim.npz and sim.json). `trajectotree simulate` and a sweep's trials and
executions share them."""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trajectotree.config import Config, ConfigError, config_from_dict
from trajectotree.io import (
    PLAN_JSON,
    PLAN_NPZ,
    SIM_JSON,
    SIM_NPZ,
    reading,
    require_files,
    write_bytes_atomic,
    write_json_atomic,
)

# m, how far a plan's contact points may lie off the surface of the cube plan.json names (a plan's own lie on it
# to rounding; the arrays of another cube's plan miss it by millimetres), as the plane's simulate_cmd.FIT_TOL
FIT_TOL = 1e-4


def read_space_plan(plan_dir: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """plan.json's data and plan.npz's arrays (their shapes checked against each other: planning.physics.
    check_space_arrays); ConfigError naming the file and what is wrong."""
    from trajectotree.planning.physics import check_space_arrays
    from trajectotree.results import SPACE_TRAJECTORY_ARRAYS

    folder = Path(plan_dir)
    json_path, npz_path = folder / PLAN_JSON, folder / PLAN_NPZ
    require_files((json_path, npz_path), "a plan folder holds plan.json and plan.npz (written by `trajectotree plan`)")
    with reading(json_path):
        data = json.loads(json_path.read_text())
        if not isinstance(data.get("object"), dict) or not isinstance(data.get("config"), dict):
            raise ValueError("a plan in space's plan.json names its object and its config")
    with reading(npz_path), np.load(npz_path) as npz:
        arrays = {name: np.array(npz[name]) for name in npz.files}
    missing = [name for name in SPACE_TRAJECTORY_ARRAYS if name not in arrays]
    if missing:
        raise ConfigError(f"{str(npz_path)!r} lacks the array(s) {', '.join(missing)} of a plan in space")
    try:
        return data, check_space_arrays(arrays)
    except ValueError as e:
        raise ConfigError(f"{str(npz_path)!r}: {e}") from None


def check_arrays_fit_scene(npz_path: Path, arrays: dict[str, np.ndarray], scene) -> None:
    """ConfigError naming plan.npz and the mismatch when its arrays do not belong to the scene plan.json names:
    its fingers and joints the hand's, every contact point on the cube's surface at the planned pose."""
    from trajectotree.geometry import box_signed_distances, quaternion_matrices

    F, joints = scene.num_fingers, scene.tau_max.size
    if arrays["f_W"].shape[1] != F or arrays["q"].shape[1] != joints:
        raise ConfigError(
            f"{str(npz_path)!r} has {arrays['f_W'].shape[1]} fingers and {arrays['q'].shape[1]} joints; hand "
            f"{scene.hand_file.source!r} has {F} and {joints}: put the plan.json and plan.npz of one plan together"
        )
    x = arrays["x"]
    p_BC = np.einsum("kji,kfj->kfi", quaternion_matrices(x[:, :4]), arrays["p_W_C"] - x[:, None, 4:])
    off = np.abs(box_signed_distances(scene.object.half, p_BC))
    k, i = np.unravel_index(int(np.argmax(off)), off.shape)
    if off[k, i] > FIT_TOL:
        raise ConfigError(
            f"{str(npz_path)!r}: its contact points lie up to {1e3 * off[k, i]:.2f} mm off the "
            f"{' x '.join(f'{1e3 * s:g}' for s in scene.object.size)} mm cube plan.json names (finger {i} at knot "
            f"{k}; a plan's own lie on its cube within {1e3 * FIT_TOL:g} mm): put the plan.json and plan.npz of one "
            "plan together, or plan again"
        )


def save_space_sim(result, plan_dir: str | Path, plan_success: bool) -> dict:
    """PLAN_DIR/sim.npz (the result's arrays, a closed-loop run's estimates too) and sim.json (its summary, with
    `plan_success`), each written atomically; returns the summary."""
    buffer = io.BytesIO()
    arrays = {name: getattr(result, name) for name in result.ARRAYS}
    np.savez(buffer, **arrays, **({} if result.closed_loop is None else result.closed_loop.arrays()))
    write_bytes_atomic(Path(plan_dir) / SIM_NPZ, buffer.getvalue())
    summary = dict(result.to_json(), plan_success=plan_success)
    write_json_atomic(Path(plan_dir) / SIM_JSON, summary)
    return summary


@dataclass(frozen=True)
class SpacePlan:
    """What a run of a saved plan in space needs: plan.json's data, its config, the scene it names and the
    reference its arrays give."""

    data: dict  # plan.json
    config: Config  # the plan's (plan.json's config)
    scene: object  # scene.spatial.SpaceScene: the hand and the cube plan.json names, at the plan's friction
    reference: object  # execution.space_control.SpaceReference of plan.npz

    @property
    def success(self) -> bool:
        return bool(self.data.get("success"))

    @property
    def segments(self) -> int:
        """The plan's segments: its contact sequence's transitions (at least one)."""
        return max(len(self.data["contact_plan"]["contact_sequence"]) - 1, 1)


def load_space_plan(plan_dir: str | Path, config: Config | None = None) -> SpacePlan:
    """The plan in space in `plan_dir` (read_space_plan, check_arrays_fit_scene) with `config` (None: the plan's);
    ConfigError naming the file and what is wrong."""
    from trajectotree.execution.space_control import SpaceReference
    from trajectotree.scene.spatial import build_space_scene

    data, arrays = read_space_plan(plan_dir)
    if config is None:
        with reading(Path(plan_dir) / PLAN_JSON):
            config = config_from_dict(data["config"])
    cube = data["object"]
    scene = build_space_scene(
        config.scene.hand, mu=config.scene.mu, gravity=config.scene.gravity, size=cube["size"], mass=cube["mass"]
    )
    check_arrays_fit_scene(Path(plan_dir) / PLAN_NPZ, arrays, scene)
    return SpacePlan(data=data, config=config, scene=scene, reference=SpaceReference.from_arrays(arrays))
