"""Frozen dataclasses through Drake's typed YAML functions (yaml_load_typed, yaml_dump_typed).

Drake's typed loader (as in Drake's hardware_sim Scenario) checks each value's type against
the field's, rejects unknown keys and keeps the defaults of missing ones. It sets the fields of
a default-constructed dataclass one by one and has no tuples, so it fills a mutable twin of each
frozen dataclass (same fields and defaults, tuple[...] as list[...], nested dataclasses as their
twins), which `freeze` turns back into the frozen one, whose __post_init__ then checks the
values. Drake is imported on first use: importing this module (config, sweep.py) loads no Drake.

Every YAML file (a config, a hand description) is read by `read_yaml`, which bounds what a file
can cost before anything is built from it: its size (MAX_YAML_BYTES, checked before it is read),
anchors and aliases (refused at the first, so a "billion laughs" file expands nothing), nesting
(MAX_YAML_DEPTH, checked on each node's event before it is composed, so no recursion error) and
duplicate keys (refused naming both lines). It raises `YamlError`, one line saying where.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import sys
import types
import typing
from pathlib import Path

import yaml

DRAKE_ERRORS = (RuntimeError, ValueError, TypeError)  # what Drake's loader raises on a wrong key or type
# bytes, the largest YAML file read: 25 times the whole config save_config writes (2.6 kB) or 30 times the
# largest hand description (2.1 kB), and small enough that PyYAML and Drake's typed loader refuse any wrong
# value in it within about a second (a 64 KiB list for a number: 0.3 s to parse, 1 s in all on one core)
MAX_YAML_BYTES = 64 * 1024
# nested mappings and lists, at most: a config nests 5 (the file, scene, scene.object, its vertices, a vertex), a
# hand description 4 (the file, fingers, a finger, its joints)
MAX_YAML_DEPTH = 32
VALUE_CHARS = 80  # characters of a value's repr that a message repeats
MERGE_TAG = "tag:yaml.org,2002:merge"  # the "<<" key, which copies another mapping's keys (an alias's)


def clip(text: str, limit: int = VALUE_CHARS) -> str:
    """`text` cut to its first `limit` characters, saying how long it was."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def clipped_repr(value) -> str:
    """repr(`value`) as a message shows it: at most VALUE_CHARS characters of it."""
    return clip(repr(value))


class YamlError(ValueError):
    """A YAML file refused: what is wrong with it and where (line, column), in one line that names no
    file (its caller names it, "config file 'c.yaml' ...")."""


def _place(mark) -> str:
    """A PyYAML mark as a message writes it, counting from 1."""
    return f"line {mark.line + 1}, column {mark.column + 1}"


class _GuardedLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing anchors, aliases and merge keys, nesting beyond MAX_YAML_DEPTH,
    keys that are not names or repeat one, and integers too long for Python to convert, each at its
    place in the file. Every mapping the package reads (a config, a hand description) is keyed by names."""

    def __init__(self, text: str):
        super().__init__(text)
        self.depth = 0  # mappings and lists open around the node being composed

    def compose_node(self, parent, index):
        event = self.peek_event()  # a node's event, seen before the node is composed (and an alias expanded)
        if isinstance(event, yaml.AliasEvent) or event.anchor is not None:
            kind = "an alias *" if isinstance(event, yaml.AliasEvent) else "an anchor &"
            raise YamlError(
                f"has {kind}{clip(event.anchor)} at {_place(event.start_mark)}; anchors (&), aliases (*) and merge "
                "keys are refused: write each value out"
            )
        nests = isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent))
        if nests and self.depth == MAX_YAML_DEPTH:
            raise YamlError(
                f"nests mappings and lists deeper than {MAX_YAML_DEPTH} levels at {_place(event.start_mark)}; "
                f"valid: at most {MAX_YAML_DEPTH} levels"
            )
        self.depth += nests
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= nests

    def construct_mapping(self, node, deep=False):
        first = {}  # each key's first key node
        for key_node, _ in node.value:
            if key_node.tag == MERGE_TAG:
                raise YamlError(
                    f"has a merge key << at {_place(key_node.start_mark)}; merge keys, anchors (&) and aliases (*) "
                    "are refused: write each value out"
                )
            key = self.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                raise YamlError(
                    f"has key {clipped_repr(key)} at {_place(key_node.start_mark)}, which is not a name; "
                    "valid keys: names (text)"
                )
            seen = first.setdefault(key, key_node)
            if seen is not key_node:
                raise YamlError(
                    f"has key {clipped_repr(key)} twice in one mapping, at {_place(seen.start_mark)} and "
                    f"{_place(key_node.start_mark)}; give each key once"
                )
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        try:
            return super().construct_yaml_int(node)
        except ValueError:  # Python's limit on the digits of an int converted from text
            raise YamlError(
                f"has an integer of {len(node.value)} characters at {_place(node.start_mark)}; valid: at most "
                f"{sys.get_int_max_str_digits()} digits"
            ) from None


_GuardedLoader.add_constructor("tag:yaml.org,2002:int", _GuardedLoader.construct_yaml_int)


def _parse_error(error: yaml.YAMLError, text: str) -> YamlError:
    """PyYAML's error as one line: its problem and where."""
    if isinstance(error, yaml.MarkedYAMLError) and error.problem_mark is not None:
        context = f"{error.context}: " if error.context else ""  # "while parsing a flow sequence: "
        return YamlError(f"is not valid YAML: {clip(context + error.problem, 200)} at {_place(error.problem_mark)}")
    if isinstance(error, yaml.reader.ReaderError):  # a control character; its position counts characters
        line = text.count("\n", 0, error.position) + 1
        column = error.position - text.rfind("\n", 0, error.position)
        return YamlError(
            f"is not valid YAML: character #x{error.character:04x} at line {line}, column {column}: {error.reason}"
        )
    return YamlError(f"is not valid YAML: {clip(' '.join(str(error).split()), 200)}")


def _check_size(size: int) -> None:
    if size > MAX_YAML_BYTES:
        raise YamlError(
            f"is {size} bytes; valid: at most {MAX_YAML_BYTES} bytes ({MAX_YAML_BYTES // 1024} KiB), 25 times "
            "the largest config or hand description"
        )


def read_yaml(path: Path):
    """The data of YAML file `path` (PyYAML's safe types), read through the guards above; YamlError
    when the file cannot be read or is over MAX_YAML_BYTES (said before reading it), is not UTF-8 text or
    not valid YAML, or has an anchor, an alias, nesting beyond MAX_YAML_DEPTH or a duplicate key."""
    try:
        _check_size(path.stat().st_size)
        with path.open("rb") as file:
            raw = file.read(MAX_YAML_BYTES + 1)  # the size a special file (/proc) reports may not be its length
    except OSError as e:  # no permission, a name too long, a folder
        raise YamlError(f"cannot be read: {e.strerror}") from None
    _check_size(len(raw))
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise YamlError(f"is not a text file (byte {e.start} is not UTF-8); give a YAML file") from None
    return parse_yaml(text)


def parse_yaml(text: str):
    """The data of YAML `text` (a file's, or a command line's --config-text) through the same guards
    as read_yaml; YamlError as read_yaml's."""
    _check_size(len(text.encode("utf-8", "surrogatepass")))
    try:
        loader = _GuardedLoader(text)
    except yaml.YAMLError as e:  # the reader checks every character first
        raise _parse_error(e, text) from None
    try:
        return loader.get_single_data()
    except yaml.YAMLError as e:
        raise _parse_error(e, text) from None
    finally:
        loader.dispose()


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


def _optional(kind) -> tuple[type, bool]:
    """(the type, whether None is allowed) of a field of type `kind` (X or X | None)."""
    if typing.get_origin(kind) in (typing.Union, types.UnionType):  # X | None, the only union in the config
        return typing.get_args(kind)[0], True
    return kind, False


def _frozen(kind, value):
    """`value`, filled by Drake's loader for a field of type `kind`, as the frozen field takes it:
    lists as tuples, dataclass twins as their frozen dataclasses, at any depth."""
    kind, _ = _optional(kind)
    if value is None:
        return None
    if dc.is_dataclass(kind):
        return freeze(kind, value)
    if typing.get_origin(kind) is tuple:
        return tuple(_frozen(typing.get_args(kind)[0], v) for v in value)
    return value


def freeze(cls, loaded):
    """Frozen dataclass `cls` from its filled twin (lists back to tuples, nested dataclasses
    frozen too; __post_init__ checks the values)."""
    hints = typing.get_type_hints(cls)
    return cls(**{f.name: _frozen(hints[f.name], getattr(loaded, f.name)) for f in dc.fields(cls)})


def _type_name(kind) -> str:
    return kind.__name__ if isinstance(kind, type) else str(kind)  # float, tuple[float, float, float]


def _check(cls, data, path: str, leaves: bool) -> None:
    """YamlError naming the first key of mapping `data` (for dataclass `cls`, at `path`) that does not
    fit the schema: an unknown key, anything but a mapping for a dataclass or anything but a list for a
    tuple (Drake's loader would split a string into its characters), and with `leaves`, a value Drake's
    loader refuses, loaded alone because Drake's own message may name only the value."""
    hints = typing.get_type_hints(cls)
    if not isinstance(data, dict):
        raise YamlError(f"{path or 'the file'} must be a mapping with keys {list(hints)}, got {clipped_repr(data)}")
    for key, value in data.items():
        name = f"{path}.{clip(str(key))}" if path else clip(str(key))
        if key not in hints:
            raise YamlError(f"{name}: unknown key; valid keys: {list(hints)}")
        kind, optional = _optional(hints[key])
        if value is None and optional:
            continue
        element = typing.get_args(kind)[0] if typing.get_origin(kind) is tuple else None
        if dc.is_dataclass(kind):
            _check(kind, value, name, leaves)
        elif element is not None and not isinstance(value, list):
            raise YamlError(f"{name} = {clipped_repr(value)} is not a list; expected {_type_name(hints[key])}")
        elif dc.is_dataclass(element):
            for i, entry in enumerate(value):
                _check(element, entry, f"{name}[{i}]", leaves)
        elif leaves:
            try:
                _load(cls, {key: value})
            except DRAKE_ERRORS as e:
                raise YamlError(
                    f"{name} = {clipped_repr(value)}: {clip(str(e), 200)}; expected {_type_name(hints[key])}"
                ) from None


def _load(cls, data: dict, defaults=None):
    yaml = drake_yaml()
    return yaml.yaml_load_typed(schema=schema(cls), data=yaml.yaml_dump(data), defaults=defaults)


def load_typed(cls, data, path: str = "", defaults=None):
    """Frozen dataclass `cls` from mapping `data` through Drake's typed loader (passed as YAML text:
    floats exactly, as repr), on top of `defaults` (an instance of `cls`: the keys `data` gives replace
    its fields, nested dataclasses key by key, as yaml_load_typed's defaults; None: the defaults of
    `cls`), so that a file and then YAML text layer as Drake's own overrides do. YamlError naming the
    key at `path` ("controller.grasp.tip_kp") Drake refuses; the frozen dataclass checks the values."""
    _check(cls, data, path, leaves=False)
    try:
        loaded = _load(cls, data, None if defaults is None else thaw(defaults))
    except DRAKE_ERRORS as e:
        _check(cls, data, path, leaves=True)
        raise YamlError(f"{path or 'the file'}: {clip(str(e), 200)}") from None
    return freeze(cls, loaded)
