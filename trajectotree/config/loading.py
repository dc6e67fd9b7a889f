"""One typed loader for every configuration: `Config` (its sections scene, search, cito, controller,
sim, goal) from a YAML file, YAML text or the nested dicts of plan.json and sweep manifests.

Each section is loaded by Drake's typed YAML functions (yaml_load_typed, yaml_dump_typed, through
trajectotree.typed_yaml), which check each value's type, on top of the config so far, so that
settings layer as Drake's own overrides do: the defaults (or a plan's config), then a file
(`load_config`), then YAML text (`apply_config_text`, the commands' --config-text). Files and text
are read within typed_yaml.read_yaml's limits (size, anchors, nesting, duplicate keys). A refused
key or value is a ConfigError naming where it came from and the key ("controller.grasp.tip_kp").
"""

from __future__ import annotations

import dataclasses as dc
from dataclasses import dataclass, field
from pathlib import Path

from trajectotree.config.checks import ConfigError, is_file
from trajectotree.config.cito import CitoConfig
from trajectotree.config.controller import ControllerGains, nest_flat_keys
from trajectotree.config.scene import SceneConfig
from trajectotree.config.search import GoalPose, SearchConfig
from trajectotree.config.sim import SimConfig
from trajectotree.typed_yaml import YamlError, clipped_repr, drake_yaml, load_typed, parse_yaml, read_yaml, thaw


@dataclass(frozen=True)
class Config:
    """Everything one trial uses; saved into every plan.json."""

    scene: SceneConfig = field(default_factory=SceneConfig)
    search: SearchConfig = field(default_factory=SearchConfig)
    cito: CitoConfig = field(default_factory=CitoConfig)
    controller: ControllerGains = field(default_factory=ControllerGains)
    sim: SimConfig = field(default_factory=SimConfig)
    # the task's goal when a config file gives it (the CLI's --goal and --goal-pose override it); a
    # plan's config holds the goal it was planned for
    goal: GoalPose = field(default_factory=GoalPose)


def _load_section(cls, data, name: str, where: str, defaults=None):
    """Section `name` (dataclass `cls`) from its mapping `data` on top of `defaults` (None: the
    section's defaults; data None: `defaults` unchanged)."""
    if data is None:
        return cls() if defaults is None else defaults
    if not isinstance(data, dict):
        raise ConfigError(f"{where} section {name} must be a mapping, got {clipped_repr(data)}")
    try:
        return load_typed(cls, data, name, defaults)
    except YamlError as e:
        raise ConfigError(f"{where}: {e}") from None


def config_from_dict(data: dict, where: str = "config", base: Config | None = None) -> Config:
    """A Config from nested dicts (from YAML, plan.json or a sweep manifest) on top of `base` (None:
    the defaults); each section is loaded alone, so an error names its section. `where` names the
    source in messages."""
    base = Config() if base is None else base
    if data is None:
        return base
    if not isinstance(data, dict):
        raise ConfigError(f"{where} must be a mapping, got {clipped_repr(data)}")
    data = _upgraded(data)
    sections = {f.name: f.default_factory for f in dc.fields(Config)}
    unknown = sorted(set(data) - set(sections))
    if unknown:
        raise ConfigError(f"unknown key(s) {clipped_repr(unknown)} in {where}; valid keys: {sorted(sections)}")
    return dc.replace(
        base,
        **{
            name: _load_section(sections[name], value, name, where, getattr(base, name)) for name, value in data.items()
        },
    )


def _upgraded(data: dict) -> dict:
    """`data` in today's layout from plan.json files written before the controller's groups: its flat
    controller keys nested (controller.nest_flat_keys) and sim.replan moved to controller.replan."""
    controller, sim = data.get("controller"), data.get("sim")
    if isinstance(controller, dict):
        data = {**data, "controller": nest_flat_keys(controller)}
    if isinstance(sim, dict) and "replan" in sim:
        replan = sim["replan"]
        sim = {k: v for k, v in sim.items() if k != "replan"}
        data = {**data, "sim": sim, "controller": {**(data.get("controller") or {}), "replan": replan}}
    return data


def config_to_dict(config: Config) -> dict:
    """Plain nested dicts (tuples as lists), suitable for JSON and YAML: read off the frozen dataclasses
    themselves, not through their mutable twins (typed_yaml.thaw), whose classes only Drake's loader needs
    (making them costs a `plan` process 15-30 ms, issue 35)."""
    return _plain(config)


def _plain(value):
    """`value` with its dataclasses as dicts and its tuples as lists, at any depth."""
    if dc.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dc.fields(value)}
    return [_plain(v) for v in value] if isinstance(value, (tuple, list)) else value


def config_file_data(path: str | Path):
    """The data of config file `path` (typed_yaml.read_yaml: size, anchors, nesting and duplicate keys
    bounded); ConfigError naming the file."""
    path = Path(path)
    try:
        if path.is_dir():
            raise ConfigError(f"config file {str(path)!r} is a folder; give a YAML file")
        if not is_file(path):
            raise ConfigError(f"config file {str(path)!r} does not exist")
        return read_yaml(path)
    except YamlError as e:
        raise ConfigError(f"config file {str(path)!r} {e}") from None
    except OSError as e:  # a name too long to look up
        raise ConfigError(f"config file {str(path)!r} cannot be read: {e.strerror}") from None


def load_config(path: str | Path, base: Config | None = None) -> Config:
    """Reads a YAML file on top of `base` (None: the defaults); missing keys keep their values,
    unknown keys are errors."""
    data = config_file_data(path)
    path = Path(path)
    if data is None:  # empty, comments only or null: more often a file not yet written than a wish for defaults
        raise ConfigError(
            f"config file {str(path)!r} holds no settings (it is empty, or only comments or null); write the "
            "fields to change, {} for the defaults, or give no config file"
        )
    return config_from_dict(data, f"config file {str(path)!r}", base)


def config_text_data(text: str) -> dict:
    """The mapping of --config-text YAML `text` (read as a file is: typed_yaml.parse_yaml)."""
    try:
        data = parse_yaml(text)
    except YamlError as e:
        raise ConfigError(f"--config-text {e}") from None
    if not isinstance(data, dict):
        raise ConfigError(
            f"--config-text {clipped_repr(text)} is not a mapping of sections; give YAML such as "
            "'{controller: {grasp: {tip_kp: 80}}}'"
        )
    return data


def apply_config_text(config: Config, text: str) -> Config:
    """`config` with the settings of YAML `text` on top (the commands' --config-text, applied after
    --config's file): e.g. "{controller: {grasp: {tip_kp: 80}}}" changes that field alone."""
    return config_from_dict(config_text_data(text), "--config-text", config)


def save_config(config: Config, path: str | Path) -> None:
    """Writes every field as YAML (Drake's yaml_dump_typed); `load_config` reads it back equal."""
    drake_yaml().yaml_dump_typed(thaw(config), filename=str(path))


def with_values(section, values: dict):
    """Frozen dataclass `section` (a Config, or any section of it) with the fields `values` names by
    dotted path ({"controller.grasp.tip_kp": 80.0}) replaced, each nested dataclass rebuilt (and so
    checked) on the way up."""
    changes: dict = {}
    for path, value in values.items():
        head, _, rest = path.partition(".")
        changes.setdefault(head, {} if rest else value)
        if rest:
            changes[head][rest] = value
    return dc.replace(
        section,
        **{
            name: with_values(getattr(section, name), value) if isinstance(value, dict) else value
            for name, value in changes.items()
        },
    )
