"""A `trajectotree plan` process's start (issue 35): config_to_dict reads the frozen config itself, as
the mutable twins Drake's loader fills would give it, and a planar plan imports no search in space."""

import dataclasses
import json
import subprocess
import sys

from trajectotree.config import Config, config_from_dict, config_to_dict, load_config
from trajectotree.typed_yaml import thaw

POLYGON = {"scene": {"object": {"vertices": [[0.1, 0.0], [0.0, 0.08], [-0.09, -0.02]]}, "initial_pose": [0.01, 0, 0]}}


def test_config_to_dict_is_the_twins_dict():
    for config in (Config(), load_config("configs/paper.yaml"), config_from_dict(POLYGON)):
        plain = config_to_dict(config)
        assert plain == dataclasses.asdict(thaw(config))
        assert json.dumps(plain) == json.dumps(dataclasses.asdict(thaw(config)))  # lists where tuples were


def test_config_to_dict_makes_no_twin_classes():
    code = (
        "from trajectotree.config import Config, config_to_dict\n"
        "from trajectotree.typed_yaml import schema\n"
        "config_to_dict(Config())\n"
        "print(schema.cache_info().currsize)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "0", done.stderr


def test_planar_plan_imports_no_search_in_space(tmp_path):
    out = tmp_path / "plan"
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "trajectotree.cli", "plan", "--goal", "0.1", "--segments", "1"]
        + ["--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    imported = {line.split("|")[-1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")}
    assert "trajectotree.planning.piece" in imported  # the list is the process's
    assert not {"trajectotree.search.space_tree", "trajectotree.search.spatial_reach"} & imported
    assert (out / "plan.json").is_file()
