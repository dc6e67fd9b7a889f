"""TrajectoTree: contact-sequence tree search meets contact-implicit trajectory optimization.

The public API, by stage of the data flow (units: m, kg, s, rad, N, N m)::

    import trajectotree as tt
    result = tt.plan(goal=1.57)             # search + CITO -> PlanResult (plan.npz arrays, physics check)
    run = tt.run_simulation(plan=result)    # full-dynamics Drake execution -> SimResult (drops, errors)
    tt.save_plan(result, "out")             # out/plan.json + out/plan.npz

Configuration is typed and frozen: Config(scene=SceneConfig(...), search=SearchConfig(...), ...),
or load_config("file.yaml"); tt.plan also takes the file's path or a mapping of its sections, and
refuses before any planning what the CLI refuses (ConfigError; trajectotree.planning.request). Names
are imported on first use, so `import trajectotree` stays light (and the values modules never pull in Drake).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# Public name -> the module that defines it.
_EXPORTS = {
    # values
    "Config": "config",
    "SceneConfig": "config",
    "ObjectConfig": "config",
    "SearchConfig": "config",
    "CitoConfig": "config",
    "ControllerGains": "config",
    "SimConfig": "config",
    "ConfigError": "config",
    "load_config": "config",
    "save_config": "config",
    "ContactPlan": "contact_plan",
    "ContactNode": "contact_plan",
    "PlanResult": "results",
    "SimResult": "results",
    "PhysicsCheck": "results",
    "StartState": "start",
    "save_plan": "io",
    "load_plan": "io",
    "save_sim": "io",
    "load_sim": "io",
    "save_start": "io",
    "load_start": "io",
    # stages
    "build_scene": "scene.plant",
    "find_contact_plan": "search.tree",
    "plan": "planning.planners",
    "check_physics": "planning.physics",
    "run_simulation": "execution.run",
    "add_executor": "execution.executor",
    "Executor": "config.executor",
    "write_plan_html": "execution.playback",
}
__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'trajectotree' has no attribute {name!r}")
    return getattr(importlib.import_module(f"trajectotree.{_EXPORTS[name]}"), name)


def __dir__() -> list[str]:
    return sorted(__all__)
