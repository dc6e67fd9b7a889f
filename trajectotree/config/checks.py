"""ConfigError and the checks that build its messages (field, value, valid range), shared by every
configuration section and by the commands' own options."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

from trajectotree.typed_yaml import clipped_repr

_NO_VALUE = object()  # a ConfigError about a field whose value its message does not repeat
MAX_FORCE = 100.0  # N, any force bound or threshold: ten times what the 1 N m motors push at 0.1 m
MAX_WEIGHT = 1e8  # 1, any cost weight: with the others near 1, double precision keeps 8 digits of the cost


class ConfigError(ValueError):
    """An invalid configuration or command-line value (CLI exit code 2).

    An error about one value carries its `field` (a config field such as "scene.box_mass", or an
    option such as "--goal"), the element `index` within it, the `value` given (`shown` writes it
    otherwise than repr), what is wrong with it (`problem`: "is out of range", or after a colon a
    sentence of its own) and the `valid` range or `choices` (`label` names them otherwise than
    "valid range" / "valid"). Its message is built from them, so the CLI can name the option that
    set the field (`as_option`). An error about anything else (a file, two options together) is
    its message alone, with field None."""

    def __init__(
        self,
        message: str | None = None,
        *,
        field: str | None = None,
        value=_NO_VALUE,
        problem: str = "is out of range",
        valid: str | None = None,
        choices: tuple[str, ...] | None = None,
        index: tuple[int, ...] = (),
        shown: str | None = None,
        label: str | None = None,
        option: str | None = None,
    ):
        if (message is None) == (field is None):
            raise TypeError("ConfigError takes a message or a field, not both")
        self.field, self.value, self.problem, self.index = field, value, problem, index
        self.valid = ", ".join(choices) if choices is not None else valid
        self.choices, self.shown, self.label, self.option = choices, shown, label, option
        super().__init__(message if field is None else self._text())

    @property
    def subject(self) -> str:
        """How the message names the value: the field with its index, after the option that set it."""
        named = self.field + "".join(f"[{i}]" for i in self.index)
        return named if self.option is None else f"{self.option} ({named})"

    def _text(self) -> str:
        if self.value is _NO_VALUE:
            text = f"{self.subject}: {self.problem}"
        else:
            joint = "" if self.problem.startswith(":") else " "  # "is out of range", or ": a sentence of its own"
            text = f"{self.subject} = {self.shown or clipped_repr(self.value)}{joint}{self.problem}"
        if self.valid is not None:
            label = self.label or ("valid" if self.choices is not None else "valid range")
            text += f"; {label}: {self.valid}"
        return text

    def as_option(self, option: str) -> ConfigError:
        """The same error, naming the command-line `option` that set its field."""
        return ConfigError(
            field=self.field,
            value=self.value,
            problem=self.problem,
            valid=self.valid,
            choices=self.choices,
            index=self.index,
            shown=self.shown,
            label=self.label,
            option=option,
        )


def interval(low: float | None, high: float | None, *, low_open: bool = False, high_open: bool = False) -> str:
    """[low, high] as a message writes it, open at an infinite or an excluded end."""
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    return f"{'(' if low_open or low is None else '['}{lo}, {hi}{')' if high_open or high is None else ']'}"


def check_range(
    name: str,
    value,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    index: tuple[int, ...] = (),
) -> None:
    """Raises ConfigError naming `name` (element `index`) unless `value` is a finite number
    within [low, high]."""
    valid = interval(low, high, low_open=low_open, high_open=high_open)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(field=name, index=index, value=value, problem="is not a finite number", valid=valid)
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and (value >= high if high_open else value > high)
    if too_low or too_high:
        raise ConfigError(field=name, index=index, value=value, valid=valid)


def check_integer(name: str, value, low: int, high: int | None = None) -> None:
    """Raises ConfigError naming `name` unless `value` is an integer within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(
            field=name, value=value, problem="is not an integer", valid=f"integers in {interval(low, high)}"
        )
    check_range(name, value, low, high)


def check_bool(name: str, value) -> None:
    """Raises ConfigError naming `name` unless `value` is true or false."""
    if not isinstance(value, bool):
        raise ConfigError(field=name, value=value, problem="is not true or false", choices=("true", "false"))


def check_length(name: str, value, length: int, entries: str) -> None:
    """Raises ConfigError naming `name` unless `value` has `length` entries (`entries` says which)."""
    if len(value) != length:
        raise ConfigError(field=name, value=value, problem=f"has {len(value)} entries", valid=f"{length}: {entries}")


def is_file(path: str | Path) -> bool:
    """Path.is_file, but False for a path the system cannot look up at all (a name longer than
    NAME_MAX, ENAMETOOLONG), which Path.is_file raises as OSError: no such file can exist."""
    try:
        return Path(path).is_file()
    except OSError:
        return False


@dataclass(frozen=True)
class Range:
    """A field's unit and valid range, written beside the field (`ranged`) and checked by
    `check_fields`. A bound is a number, None (unbounded) or the name of a sibling field whose
    value it is (max_normal_force above min_normal_force)."""

    unit: str  # as messages write it after the range: "N/m", "s", "1" (dimensionless)
    low: float | str | None = None
    high: float | str | None = None
    low_open: bool = False
    high_open: bool = False
    integer: bool = False

    def bound(self, section, end: float | str | None) -> float | None:
        return getattr(section, end) if isinstance(end, str) else end

    def check(self, section, name: str, value, index: tuple[int, ...] = ()) -> None:
        """ConfigError naming `name` (element `index`) unless `value` is within this range."""
        low, high = self.bound(section, self.low), self.bound(section, self.high)
        if self.integer:
            check_integer(name, value, low, high)
            return
        try:
            check_range(name, value, low, high, low_open=self.low_open, high_open=self.high_open, index=index)
        except ConfigError as e:
            unit = "" if self.unit == "1" else f" {self.unit}"
            raise ConfigError(
                field=e.field, index=e.index, value=e.value, problem=e.problem, valid=e.valid + unit
            ) from None


def ranged(default, unit: str, low=None, high=None, **bounds) -> float:
    """A dataclass field with its default, unit and valid range (Range's arguments), which
    `check_fields` checks. Given a tuple of Ranges as `unit`, each entry of a tuple field has its own."""
    limits = unit if isinstance(unit, tuple) else Range(unit, low, high, **bounds)
    return field(default=default, metadata={"range": limits})


def flag(default: bool) -> bool:
    """A true-or-false dataclass field, which `check_fields` checks."""
    return field(default=default, metadata={"flag": True})


def check_fields(section, prefix: str) -> None:
    """ConfigError naming the first field of dataclass `section` (as `prefix`.field) outside the
    range written beside it (`ranged`, `flag`)."""
    for f in fields(section):
        value, name = getattr(section, f.name), f"{prefix}.{f.name}"
        if f.metadata.get("flag"):
            check_bool(name, value)
        limits = f.metadata.get("range")
        if isinstance(limits, Range):
            limits.check(section, name, value)
        elif limits is not None:
            units = ", ".join(r.unit for r in limits)
            check_length(name, value, len(limits), units)
            for i, (r, v) in enumerate(zip(limits, value)):
                r.check(section, name, v, index=(i,))
