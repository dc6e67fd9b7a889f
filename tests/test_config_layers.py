"""The controller's settings grouped by concern with each field's unit and range beside it, one
typed loader layering a file and then YAML text (--config-text), and plan.json files written with
the flat controller keys still executing with their settings."""

import dataclasses
import subprocess
import sys
import typing
from pathlib import Path

import pytest

from trajectotree.cli import main
from trajectotree.config import (
    Config,
    ConfigError,
    ControllerGains,
    Range,
    apply_config_text,
    config_from_dict,
    config_to_dict,
    load_config,
    with_values,
)

GROUPS = ("impedance", "grasp", "estimators", "push_reflex", "landing_reflex", "replan")


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("group", GROUPS)
def test_every_controller_field_has_its_unit_and_range_beside_it(group):
    cls = typing.get_type_hints(ControllerGains)[group]
    for f in dataclasses.fields(cls):
        limits = f.metadata.get("range")
        assert f.metadata.get("flag") or limits is not None, f.name
        for r in limits if isinstance(limits, tuple) else () if limits is None else (limits,):
            assert isinstance(r, Range) and r.unit and r.high is not None, f.name


def test_a_value_outside_its_range_names_the_group_the_value_the_range_and_the_unit():
    with pytest.raises(ConfigError) as info:
        with_values(Config(), {"controller.landing_reflex.tip_kd": 6.0})
    assert str(info.value) == "controller.landing_reflex.tip_kd = 6.0 is out of range; valid range: [0, 5] N s/m"
    # a bound that is another group's field: the reflex's squeeze within the grasp QP's largest push
    with pytest.raises(ConfigError, match=r"controller.push_reflex.squeeze = 9.0 .*valid range: \[0, 8\] N"):
        with_values(Config(), {"controller.push_reflex.squeeze": 9.0})


def test_text_layers_on_the_file_as_yaml_load_typed_defaults_do(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("controller:\n  grasp: {tip_kp: 70.0, tip_kd: 2.0}\n  rate_hz: 400.0\n")
    config = apply_config_text(load_config(path), "{controller: {grasp: {tip_kp: 90}}}")
    grasp = config.controller.grasp
    assert (grasp.tip_kp, grasp.tip_kd, config.controller.rate_hz) == (90.0, 2.0, 400.0)
    assert grasp.object_kp == Config().controller.grasp.object_kp  # neither layer names it: the default


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "{controller: {grasp: {tip_kpp: 80}}}",
            "--config-text: controller.grasp.tip_kpp: unknown key; valid keys: ['object_kp',",
        ),
        ("{controller: {grasp: {tip_kp: 1e9}}}", "controller.grasp.tip_kp = 1000000000.0 is out of range; valid range"),
        ("{controller: {grasp: {tip_kp: soft}}}", "--config-text: controller.grasp.tip_kp = 'soft': "),
        ("[1, 2]", "--config-text '[1, 2]' is not a mapping of sections"),
    ],
)
def test_bad_config_text_is_refused_in_one_line_before_anything_is_written(tmp_path, capsys, text, message):
    out = tmp_path / "plan"
    assert main(["plan", "--goal", "0.1", "--segments", "1", "--config-text", text, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and message in captured.err, captured.err
    assert listing(tmp_path) == []


def test_config_text_reaches_the_scene_in_a_subprocess(tmp_path):
    """The scene command reads --config-text on top of --config: the mass of the text, the width of the file."""
    path = tmp_path / "c.yaml"
    path.write_text("scene: {box_width: 0.18, box_mass: 0.2}\n")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "trajectotree.cli",
            "scene",
            "--config",
            str(path),
            "--config-text",
            "{scene: {box_mass: 0.07}}",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("object: 0.180 x 0.100 m box, 0.070 kg,"), out.stdout


def test_a_plan_json_with_the_flat_controller_keys_loads_them_into_their_groups():
    flat = {"controller": {"tip_kp": 60.0, "reflex_squeeze": 3.0, "land_lag": 0.03, "kp": 300.0, "rate_hz": 250.0}}
    flat["sim"] = {"settle_time": 0.2, "replan": {"max_replans": 2}}
    config = config_from_dict(flat, "plan.json")
    c = config.controller
    assert (c.grasp.tip_kp, c.push_reflex.squeeze, c.landing_reflex.lag, c.impedance.kp) == (60.0, 3.0, 0.03, 300.0)
    assert (c.rate_hz, c.replan.max_replans, config.sim.settle_time) == (250.0, 2, 0.2)
    assert config_from_dict(config_to_dict(config)) == config  # today's layout round-trips


def test_text_where_a_list_belongs_is_refused_not_split_into_characters():
    """Drake's loader reads "123" for a list of floats as (1.0, 2.0, 3.0): the schema check refuses it first."""
    with pytest.raises(ConfigError, match=r"search.initial_arclengths = '123' is not a list; expected"):
        apply_config_text(Config(), "{search: {initial_arclengths: '123'}}")
