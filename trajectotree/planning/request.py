"""What a plan is asked for, checked before any planning: the one validation path of `tt.plan`
(trajectotree.planning.planners.plan) and of the commands that plan (`trajectotree plan`, `demo`,
`search` and `sweep`, through trajectotree.cli.common, which names the options that set a field).

`check_plan_request` takes the API's forms of each input (a config as a Config, the path of a YAML
file or a mapping; a start as a StartState, a mapping as in start.json or the path of one) and
refuses, with a ConfigError naming the value and its limit, what no plan can come of: an unknown
method, a goal out of range or out of the hand's workspace, a start the hand cannot plan from, an
object the hand cannot grasp at its initial pose or cannot hold the weight of.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from trajectotree.cito.hand import check_cito_hand
from trajectotree.config import MIN_BOX_MASS, Config, ConfigError, GoalPose, config_from_dict, load_config, mu_plan
from trajectotree.io import load_start
from trajectotree.planning.segment_pool import check_workers
from trajectotree.planning.start import start_config
from trajectotree.results import check_goal, check_method
from trajectotree.scene.plant import Scene, build_scene, describe_object, plant_key
from trajectotree.search.initial_grasp import GraspCandidates, GraspTables, initial_grasp_candidates
from trajectotree.search.payload import payload
from trajectotree.search.workspace import check_goal_position
from trajectotree.start import StartState


@dataclass(frozen=True)
class PlanRequest:
    """A plan's inputs, checked (check_plan_request)."""

    method: str
    goal: GoalPose
    config: Config  # with a start: rooted at its pose and grasp (planning.start.start_config)
    scene: Scene  # config.scene's (with a start on the plant of the scene given: Scene.for_planning)
    start: StartState | None
    segment_workers: int | None
    # the object is heavier than three fingers hold while the fourth lets go: only plans that
    # switch no finger can be found (not raised; the CLI prints it, tt.plan warns)
    warning: ConfigError | None = None


def as_config(config) -> Config:
    """`config` as a Config: None (the defaults), a Config, the path (str or Path) of a YAML file
    (load_config) or a mapping of its sections (config_from_dict); ConfigError otherwise."""
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, (str, Path)):
        return load_config(config)
    if isinstance(config, Mapping):
        return config_from_dict(dict(config), "config")
    raise ConfigError(
        f"config = {config!r} is of type {type(config).__name__}; give a Config, the path (str or Path) of a YAML "
        "config file, or a mapping of its sections"
    )


def as_start(start) -> StartState | None:
    """`start` as a StartState: None, a StartState, a mapping as in start.json or the path (str or
    Path) of a start.json file; ConfigError otherwise."""
    if start is None or isinstance(start, StartState):
        return start
    if isinstance(start, (str, Path)):
        return load_start(start, "start")
    if isinstance(start, Mapping):
        return StartState.from_json(dict(start), where="start")
    raise ConfigError(
        f"start = {start!r} is of type {type(start).__name__}; give a StartState, a mapping as in start.json "
        "(object_pose, q, optionally object_velocity and arclengths) or the path of a start.json file"
    )


def check_plan_request(
    *,
    goal=None,
    method: str = "trajectotree",
    config=None,
    scene: Scene | None = None,
    start=None,
    segment_workers: int | None = None,
    grasp_tables: GraspTables | None = None,
    grasp_given: bool = False,
    goal_name: str = "goal.position",
) -> PlanRequest:
    """The checked request of planners.plan's arguments of the same names (ConfigError naming the
    value and its limit otherwise). Without a start the hand must grasp the object at
    scene.initial_pose and hold its weight (check_graspable), unless `grasp_given` (a contact plan
    given: there is no search to root); `grasp_tables` keeps the ranked initial grasps for the
    search. `goal_name` names a goal position out of the workspace ("--goal-pose X Y" for the CLI)."""
    method = check_method(method)
    config = as_config(config)
    goal = check_goal(config.goal if goal is None else goal)
    start = as_start(start)
    check_workers(segment_workers)
    scene = scene or build_scene(config.scene)
    if start is not None:  # the scene given is the object's, for the start's contacts
        config = start_config(scene, start, config)
        same_plant = plant_key(config.scene) == plant_key(scene.config)
        scene = scene.for_planning(config.scene) if same_plant else build_scene(config.scene)
    elif scene.config != config.scene:
        raise ConfigError("scene was built from a different SceneConfig than config.scene")
    check_cito_hand(scene)
    warning = None if start is not None or grasp_given else check_graspable(scene, config, grasp_tables)
    check_goal_position(scene, config.search, goal, goal_name)
    return PlanRequest(method, goal, config, scene, start, segment_workers, warning)


def check_graspable(scene: Scene, config: Config, tables: GraspTables | None = None) -> ConfigError | None:
    """ConfigError (before any planning) when the hand has no initial grasp of the object at
    scene.initial_pose (trajectotree.search.initial_grasp: a finger reaches no corner-free contact,
    or no three-finger stance holds at mu_plan), unless search.initial_arclengths sets the grasp,
    or when the object is heavier than the hand can hold (check_payload, whose warning it returns)."""
    if config.search.initial_arclengths is not None:
        return check_payload(scene, config)
    # Without `tables` the planner ranks the grasps again inside its timed search, so search_time_s includes them.
    grasps = initial_grasp_candidates(scene, config.search) if tables is None else tables.get(scene, config.search)
    if grasps.refusal is not None:
        problem = (
            f"the hand cannot grasp the {describe_object(config.scene)} at scene.initial_pose "
            f"{list(config.scene.initial_pose)}: {grasps.refusal}; corner-free contacts each finger "
            f"reaches: {list(grasps.reachable)} (see `trajectotree scene ... --figure FILE.png`)"
        )
        if config.scene.object.is_box:
            raise ConfigError(f"the box: {problem}")
        raise ConfigError(field=config.scene.object.field_name, problem=problem)
    return check_payload(scene, config, grasps)


def floor_digits(value: float, digits: int = 3) -> float:
    """`value` rounded down to `digits` significant digits, so that a limit printed as a bound
    is itself within it (3.2262 kg prints as 3.22, which the check accepts)."""
    if not math.isfinite(value) or value <= 0:
        return value
    scale = 10.0 ** (digits - 1 - math.floor(math.log10(value)))
    return math.floor(value * scale) / scale


def check_payload(scene: Scene, config: Config, grasps: GraspCandidates | None = None) -> ConfigError | None:
    """ConfigError (before any planning) when no initial grasp holds the object's weight at rest
    within the joint torque limits (trajectotree.search.payload: no plan can exist). Returned, not
    raised: the warning when it is lighter than that but no three-finger stance carries it while
    the fourth finger lets go (the search can then only find plans that switch no finger)."""
    mass = config.scene.box_mass
    if grasps is None and config.search.initial_arclengths is None:
        grasps = initial_grasp_candidates(scene, config.search)  # as check_graspable: outside the timed search
    quick = payload(scene, config.search, grasps, first=1)  # the best grasp usually holds it: one small LP
    if quick is None or (quick.hold_kg >= mass and quick.switch_kg >= mass):
        return None
    limits = payload(scene, config.search, grasps)
    where = (
        f"at scene.initial_pose {list(config.scene.initial_pose)} with friction mu_plan "
        f"{mu_plan(config.scene, config.search):.3g} and each joint within its {limits.tau_max:g} N m "
        f"torque limit (the links' own weight included)"
    )
    grasps_text = (
        "search.initial_arclengths' grasp"
        if config.search.initial_arclengths is not None
        else f"the strongest of the {limits.grasps} candidate initial grasps"
    )
    if mass > limits.hold_kg:
        hold = floor_digits(limits.hold_kg)
        raise ConfigError(
            field="scene.box_mass",
            value=mass,
            shown=f"{mass!r} kg",
            problem=f"is more than the hand can hold: {grasps_text} holds at most {hold:g} kg at rest with four "
            f"fingers {where}",
            valid=f"[{MIN_BOX_MASS:g}, {hold:g}] kg",
        )
    if mass <= limits.switch_kg:
        return None
    cap = config.search.max_stance_force
    return ConfigError(
        field="scene.box_mass",
        value=mass,
        shown=f"{mass!r} kg",
        problem=f"is more than three fingers can hold while the fourth lets go: at "
        f"most {floor_digits(limits.switch_kg):g} kg ({grasps_text.replace('the strongest of ', '')}, {where}"
        + (f", at most search.max_stance_force {cap:g} N of normal force in total" if cap else "")
        + "); only plans that switch no finger (small rotations) can be found",
    )
