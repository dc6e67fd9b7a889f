"""The wheel: it holds every module and the models/ folder, and an installed copy (not the
editable checkout) finds the models and builds the plant from them."""

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
SOURCES = ("pyproject.toml", "README.md", "trajectotree", "models")  # what the build reads

INSTALLED_CHECK = """
import sys
from pathlib import Path
import trajectotree
from trajectotree.config import SceneConfig
from trajectotree.scene.plant import MODELS_DIR, build_scene
site = Path(sys.argv[1]).resolve()
assert Path(trajectotree.__file__).resolve().is_relative_to(site), trajectotree.__file__
assert Path(str(MODELS_DIR)).resolve() == site / "trajectotree" / "models", MODELS_DIR
print(build_scene(SceneConfig()).plant.num_positions(), build_scene(SceneConfig(hand="planar_hand5")).num_fingers)
"""


@pytest.mark.slow
def test_an_installed_wheel_ships_the_models_and_finds_them(tmp_path):
    source = tmp_path / "source"  # a clean copy: no build/ left over from an earlier build
    source.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(ROOT / name, source / name)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check"]
    subprocess.run([*pip, "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(source)], check=True)
    (wheel,) = (tmp_path / "dist").glob("trajectotree-*.whl")

    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(ROOT).as_posix() for p in (ROOT / "trajectotree").rglob("*.py")}
    models = {f"trajectotree/models/{p.name}" for p in (ROOT / "models").iterdir() if p.suffix in (".sdf", ".xml")}
    assert {"trajectotree/models/planar_hand.sdf", "trajectotree/models/box.sdf"} <= models
    assert modules | models <= names, sorted((modules | models) - names)

    site = tmp_path / "site"
    subprocess.run([*pip, "install", "--no-deps", "-q", "--target", str(site), str(wheel)], check=True)
    # PYTHONPATH puts the installed copy ahead of the venv's editable finder; run outside the checkout.
    result = subprocess.run(
        [sys.executable, "-c", INSTALLED_CHECK, str(site)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"},
    )
    assert result.returncode == 0, result.stderr
    # box (x, y, theta) + 8 hand joints, parsed from the shipped SDFs; and a built-in hand's YAML found beside its SDF
    assert result.stdout.split()[-2:] == ["11", "5"]
