"""`trajectotree plan --hand fingerpro4 --html`: the planned trajectory in space recorded into a self-contained
Meshcat page (execution.playback.write_space_plan_html), its legend at the plan's force scale; a bad --html path
exits 2 before the search, writing nothing."""

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.figures.legend import arrow_newtons_per_cm, arrow_scale_text

GOAL = ["--goal-rpy", "0.5", "0", "0"]


@pytest.mark.slow
def test_plan_writes_the_playback(tmp_path, capsys):
    out, page = tmp_path / "plan", tmp_path / "play.html"
    assert main(["plan", "--hand", "fingerpro4", *GOAL, "--out", str(out), "--html", str(page)]) == 0
    assert f"playback: {page}" in capsys.readouterr().out
    html = page.read_text()
    assert "<title>TrajectoTree: plan</title>" in html and "fingertips" in html
    with np.load(out / "plan.npz") as npz:
        scale = arrow_newtons_per_cm(npz["f_W"].reshape(-1, 3))
    assert f"planned force of each finger on the cube, {arrow_scale_text(scale)}" in html  # the plan's own scale
    assert len(html) > 500_000  # Meshcat's scripts inlined: the page needs no network


def test_a_bad_html_path_exits_2_before_the_search(tmp_path, capsys):
    out = tmp_path / "plan"
    argv = ["plan", "--hand", "fingerpro4", *GOAL, "--out", str(out), "--html", str(tmp_path / "play.txt")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--html" in err and "play.txt" in err
    assert list(tmp_path.iterdir()) == []
