"""Config validation, YAML round trip, and CLI exit codes for bad input."""

import json
import math
import subprocess
import sys

import pytest

from trajectotree.cli import main
from trajectotree.config import (
    CitoConfig,
    Config,
    ConfigError,
    SceneConfig,
    SearchConfig,
    config_from_dict,
    config_to_dict,
    load_config,
    save_config,
)


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("box_width", 0.0, "scene.box_width"),
        ("box_height", -0.1, "scene.box_height"),
        ("box_mass", 0.0, "scene.box_mass"),
        ("mu", 0.0, "scene.mu"),
        ("mu", math.nan, "scene.mu"),
        ("box_mass", math.inf, "scene.box_mass"),
    ],
)
def test_invalid_scene_values_name_the_field_and_range(field, value, message):
    with pytest.raises(ConfigError, match=message) as info:
        SceneConfig(**{field: value})
    assert "valid range" in str(info.value)


def test_an_error_carries_its_field_value_and_valid_range():
    with pytest.raises(ConfigError) as info:
        SceneConfig(mu=0.0)
    e = info.value
    assert (e.field, e.index, e.value, e.valid) == ("scene.mu", (), 0.0, "(0, 5]")
    assert str(e) == "scene.mu = 0.0 is out of range; valid range: (0, 5]"
    assert str(e.as_option("--mu")) == "--mu (scene.mu) = 0.0 is out of range; valid range: (0, 5]"
    with pytest.raises(ConfigError) as info:
        CitoConfig(weight_pose=(1.0, -2.0, 3.0))
    assert (info.value.field, info.value.index, info.value.value) == ("cito.weight_pose", (1,), -2.0)
    assert str(info.value).startswith("cito.weight_pose[1] = -2.0 is out of range; valid range: [0, 1e+08]")
    with pytest.raises(ConfigError) as info:
        CitoConfig(formulation="fast")
    assert info.value.choices == ("keyframes", "joint") and str(info.value).endswith("valid: keyframes, joint")
    file_error = ConfigError("config file 'x.yaml' does not exist")  # not about one value: no field
    assert file_error.field is None and str(file_error) == "config file 'x.yaml' does not exist"


def test_the_cli_names_the_option_that_set_a_field(capsys):
    assert main(["scene", "--mass", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--mass (scene.box_mass) = -1.0 is out of range; valid range: [0.001, 10]" in err


def test_search_displacements_must_be_odd():
    with pytest.raises(ConfigError, match="num_displacements"):
        SearchConfig(num_displacements=16)


def test_yaml_round_trip_and_partial_files(tmp_path):
    config = Config(scene=SceneConfig(box_width=0.16, mu=0.5))
    path = tmp_path / "c.yaml"
    save_config(config, path)
    assert load_config(path) == config
    path.write_text("scene:\n  box_mass: 0.1\n")
    loaded = load_config(path)
    assert loaded.scene.box_mass == 0.1 and loaded.scene.box_width == 0.2


@pytest.mark.parametrize(
    "text, message",
    [
        ("scene:\n  box_colour: red\n", "box_colour"),
        ("scenery: {}\n", "scenery"),
        ("scene:\n  box_mass: -2\n", "scene.box_mass"),
        ("scene: [1, 2\n", "not valid YAML"),
        # Drake's typed loader: each value must have its field's type
        ("search:\n  num_nodes: 3.5\n", "'num_nodes'"),  # an int field
        ("sim:\n  controller: 3\n", "'controller'"),  # a str field
        ("scene:\n  box_mass: [1]\n", "'box_mass'"),  # a sequence for a number
        ("scene: 3\n", "section scene must be a mapping, got 3"),
        ("scene:\n  box_mass: abc\n", "scene.box_mass = 'abc': .*; expected float"),  # Drake names only the value
    ],
)
def test_bad_yaml_is_a_named_error(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_yaml_sequences_optionals_and_numbers_load_as_the_fields_types(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("search:\n  initial_arclengths: [0.54, 0.12, 0.36, 0.48]\n  max_iter_unused: 1\n")
    with pytest.raises(ConfigError, match="max_iter_unused"):
        load_config(path)
    path.write_text(
        "search:\n  initial_arclengths: [0.54, 0.12, 0.36, 0.48]\ncito:\n  weight_pose: [1, 2, 3]\n"
        "  max_iter: 40.0\nscene:\n"
    )
    config = load_config(path)
    assert config.search.initial_arclengths == (0.54, 0.12, 0.36, 0.48)
    assert config.cito.weight_pose == (1.0, 2.0, 3.0) and all(type(w) is float for w in config.cito.weight_pose)
    assert type(config.cito.max_iter) is int and config.cito.max_iter == 40
    assert config.scene == SceneConfig()  # an empty section keeps its defaults
    save_config(config, path)
    assert load_config(path) == config
    path.write_text("search:\n  initial_arclengths: null\n")
    assert load_config(path).search.initial_arclengths is None


def test_plan_json_config_round_trip_and_unknown_keys():
    config = Config(search=SearchConfig(initial_arclengths=(0.06, 0.18, 0.32, 0.5)), cito=CitoConfig(max_iter=7))
    data = json.loads(json.dumps(config_to_dict(config)))  # as stored in plan.json
    assert config_from_dict(data) == config
    assert config_to_dict(config_from_dict(data)) == data
    data["cito"]["weight_typo"] = 1.0
    with pytest.raises(ConfigError, match="weight_typo"):
        config_from_dict(data)


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "trajectotree.cli", *args], capture_output=True, text=True)


@pytest.mark.parametrize(
    "args, message",
    [
        (["scene", "--mass", "0"], "scene.box_mass"),
        (["scene", "--mu", "nan"], "scene.mu"),
        (["scene", "--box-size", "0.2", "-0.1"], "scene.box_height"),
        (["scene", "--config", "/nonexistent.yaml"], "does not exist"),
    ],
)
def test_cli_invalid_input_exits_2(args, message, capsys):
    assert main(args) == 2  # in-process; the slow test below runs the installed entry point
    assert message in capsys.readouterr().err


def test_cli_a_bad_config_file_exits_2_naming_the_key(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text("cito:\n  max_iters: 3\n")
    assert main(["scene", "--config", str(path)]) == 2
    assert "max_iters" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_version_and_scene_summary(tmp_path):
    assert run_cli("--version").stdout.strip().startswith("trajectotree ")
    bad = run_cli("scene", "--mass", "0")
    assert bad.returncode == 2 and "scene.box_mass" in bad.stderr
    result = run_cli("scene", "--mass", "0.08", "--json", "--figure", str(tmp_path / "m.png"))
    assert result.returncode == 0, result.stderr
    assert '"mass_kg": 0.08' in result.stdout
    assert (tmp_path / "m.png").stat().st_size > 10_000


def test_round_objects_are_one_outline_each_and_round_trip_through_yaml(tmp_path):
    from trajectotree.config import ObjectConfig

    with pytest.raises(ConfigError, match="vertices and circle_radius both describe the object"):
        ObjectConfig(vertices=((0, 0), (0.1, 0), (0, 0.1)), circle_radius=0.05)
    with pytest.raises(
        ConfigError, match=r"scene.object.ellipse_semi_axes = \(0.08,\) has 1 entries; valid range: 2: a, b"
    ):
        ObjectConfig(ellipse_semi_axes=(0.08,))
    config = Config(scene=SceneConfig(object=ObjectConfig(ellipse_semi_axes=(0.08, 0.05))))
    assert not config.scene.object.is_box and ObjectConfig().is_box
    path = tmp_path / "ellipse.yaml"
    save_config(config, path)
    assert load_config(path) == config
    assert len(config.scene.shape.vertices) == 52 and config.scene.shape.edge_lengths.max() <= 0.01
