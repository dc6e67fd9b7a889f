"""The public entry to execution: `run_simulation` executes a plan open loop, closed loop
(trajectotree.execution.closed_loop) or closed loop with replanning (trajectotree.execution.replan),
and writes its playback (Meshcat, HTML, GIF) whichever the executor."""

from __future__ import annotations

from pathlib import Path

from pydrake.geometry import Meshcat

from trajectotree.config import Config, ConfigError
from trajectotree.config.executor import Executor, parse_executor
from trajectotree.execution.gif import write_gif
from trajectotree.execution.reference import reference_from_plan
from trajectotree.execution.simulate import arrow_scale, simulate_reference
from trajectotree.execution.world import Conditions, Push, parse_push
from trajectotree.figures.legend import controller_text
from trajectotree.io import GIF_SUFFIXES, HTML_SUFFIXES, check_output_file
from trajectotree.results import PlanResult, SimResult
from trajectotree.scene.plant import build_scene


def run_simulation(
    *,
    plan,
    config: Config | None = None,
    executor: Executor | str | None = None,
    meshcat: Meshcat | None = None,
    html_path: str | Path | None = None,
    gif_path: str | Path | None = None,
    sim_mu: float | None = None,
    sim_mass: float | None = None,
    push: Push | str | None = None,
    segment_workers: int | None = None,
) -> SimResult:
    """Executes `plan` (a PlanResult, or a Reference) with `executor` (an Executor or its name; None:
    config.sim.controller, open loop) in a world with friction `sim_mu`, box mass `sim_mass` (kg;
    None: the plan's) and an optional `push` (a Push or "FX,FY@T": N, N, s); the controller keeps the
    plan's values. The closed-loop executors watch the contacts, estimate the friction and the mass for
    the controller and add the reflexes (trajectotree.execution.closed_loop; the result's closed_loop
    holds what they saw). grasp-replan (a PlanResult only, since the planner needs its goal and config)
    also plans again from the measured state when the plan no longer holds, by config.controller.replan's
    rules (trajectotree.execution.replan; the result's replans list each time; the later segments of a new
    plan on `segment_workers` local processes, None: as planning.planners.plan).
    `config` defaults to the plan's own (a PlanResult's config). ConfigError on bad values. A live
    `meshcat` runs in real time; `html_path` writes the recorded playback, `gif_path` a GIF of the run
    (each checked before the run: its name's suffix, .html/.htm or .gif, and a folder that takes new
    files: io.check_output_file)."""
    if config is None:
        if not isinstance(plan, PlanResult):
            raise ConfigError("run_simulation: give config= with a Reference (only a PlanResult carries its own)")
        config = plan.config
    executor = Executor(config.sim.controller) if executor is None else parse_executor(executor)
    if isinstance(push, str):
        push = parse_push(push, config.sim.push_duration)
    conditions = Conditions(mu=sim_mu, mass=sim_mass, push=push)
    if executor.replans and not isinstance(plan, PlanResult):
        raise ConfigError("run_simulation(executor='grasp-replan'): give the PlanResult (the planner needs its goal)")
    for name, path, suffixes in (("html_path", html_path, HTML_SUFFIXES), ("gif_path", gif_path, GIF_SUFFIXES)):
        if path is not None:  # before the run, as the CLI's --html and --gif: never a run lost to its playback
            check_output_file(name, path, suffixes)
    scene = build_scene(config.scene)
    reference = reference_from_plan(plan, scene)
    result = simulate_reference(
        reference,
        config,
        executor=executor,
        meshcat=meshcat,
        html_path=html_path,
        realtime_rate=1.0 if meshcat is not None else 0.0,
        conditions=conditions,
        plan=plan if isinstance(plan, PlanResult) else None,
        segment_workers=segment_workers,
    )
    if gif_path is not None:
        write_gif(
            scene,
            result.t,
            result.x,
            result.q,
            gif_path,
            planned_poses=result.x_plan,
            forces=result.f_W,
            newtons_per_cm=arrow_scale(reference),
            title=f"simulated run, {controller_text(result.controller)}",
        )
    return result
