"""Frozen dataclasses through Drake's typed YAML functions (yaml_load_typed, yaml_dump_typed).

Drake's typed loader (as in Drake's hardware_sim Scenario) checks each value's type against
the field's, rejects unknown keys and keeps the defaults of missing ones. It sets the fields of
a default-constructed dataclass one by one and has no tuples, so it fills a mutable twin of each
frozen dataclass (same fields and defaults, tuple[...] as list[...], nested dataclasses as their
twins), which `freeze` turns back into the frozen one, whose __post_init__ then checks the
values. Drake is imported on first use: importing this module (config, sweep.py) loads no Drake.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import types
import typing

DRAKE_ERRORS = (RuntimeError, ValueError, TypeError)  # what Drake's loader raises on a wrong key or type


def drake_yaml():
    """pydrake.common.yaml, imported on first use."""
    from pydrake.common import yaml

    return yaml


def _yaml_type(kind):
    """The type Drake's loader reads for a field of type `kind`."""
    if dc.is_dataclass(kind):
        return schema(kind)
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin is tuple:
        return list[_yaml_type(args[0])]
    if origin in (typing.Union, types.UnionType):  # X | None, the only union in the config
        return _yaml_type(args[0]) | None
    return kind


@functools.cache
def schema(cls):
    """The mutable twin of frozen dataclass `cls` that Drake's typed loader fills."""
    hints, defaults = typing.get_type_hints(cls), cls()
    return dc.make_dataclass(
        cls.__name__,
        [
            (
                f.name,
                _yaml_type(hints[f.name]),
                dc.field(default_factory=functools.partial(thaw, getattr(defaults, f.name))),
            )
            for f in dc.fields(cls)
        ],
    )


def thaw(value):
    """`value` as Drake's loader and dumper take it: dataclasses as their twins, tuples as lists."""
    if dc.is_dataclass(value):
        return schema(type(value))(**{f.name: thaw(getattr(value, f.name)) for f in dc.fields(value)})
    return [thaw(v) for v in value] if isinstance(value, tuple) else value


def _tuples(value):
    """`value` with its lists, at any depth, as tuples."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def freeze(cls, loaded):
    """Frozen dataclass `cls` from its filled twin (lists back to tuples, nested dataclasses
    frozen too; __post_init__ checks the values)."""
    hints = typing.get_type_hints(cls)
    return cls(
        **{
            f.name: freeze(hints[f.name], getattr(loaded, f.name))
            if dc.is_dataclass(hints[f.name])
            else _tuples(getattr(loaded, f.name))
            for f in dc.fields(cls)
        }
    )


def load_typed(cls, data: dict):
    """The twin of `cls` filled by Drake's typed loader from mapping `data`, passed as YAML text
    (floats exactly, as repr). Raises one of DRAKE_ERRORS on a wrong key or type."""
    yaml = drake_yaml()
    return yaml.yaml_load_typed(schema=schema(cls), data=yaml.yaml_dump(data))
