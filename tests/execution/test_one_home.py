"""One home for what several stages share: building a simulation loads no plotting library (the
arrow scale and the fingers' colours live in trajectotree.figures.legend), and those colours are
matplotlib's own."""

import subprocess
import sys

import pytest

from trajectotree.figures.legend import FINGER_COLORS, FINGER_HEX, finger_rgb

BUILD = """
import sys
from trajectotree.config import Config
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.simulate import build_execution_diagram
from trajectotree.scene.plant import build_scene

scene = build_scene()
reference = static_hold_reference(scene, (0.56, 0.14, 0.26, 0.44), min_normal_force=1.0, duration=0.1, lifted=0)
build_execution_diagram(reference, Config())
print(sorted(m for m in sys.modules if m.split(".")[0] == "matplotlib"))
"""


def test_building_a_simulation_loads_no_plotting_library():
    out = subprocess.run([sys.executable, "-c", BUILD], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


@pytest.mark.parametrize("i", range(len(FINGER_COLORS)))
def test_the_fingers_colours_are_matplotlibs(i):
    from matplotlib.colors import to_hex, to_rgb

    assert to_hex(FINGER_COLORS[i]) == FINGER_HEX[i]
    assert finger_rgb(i) == to_rgb(FINGER_COLORS[i])  # the same floats: Meshcat's colours unchanged


def test_the_controller_depends_on_no_planning_stage():
    """The grasp controller reads the hand's dynamics from scene/ (HandModel), not from cito/."""
    code = (
        "import sys, trajectotree.execution.simulate; "
        "print(sorted({m.split('.')[1] for m in sys.modules if m.startswith('trajectotree.')}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "'cito'" not in out.stdout and "'search'" not in out.stdout, out.stdout
