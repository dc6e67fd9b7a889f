"""`trajectotree demo`: plan, simulate and write every promised file (small goal for speed)."""

import json

import pytest

from trajectotree.cli import main


@pytest.mark.slow
def test_demo_writes_the_plan_run_figure_playback_and_summary(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--goal", "0.3", "--segments", "2"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["files"] == [
        "plan.json",
        "plan.npz",
        "keyframes.png",
        "sim.json",
        "sim.npz",
        "playback.html",
        "forces.png",
        "summary.json",
    ]
    for name in summary["files"]:
        assert (out / name).stat().st_size > 0, name
    plan_json = json.loads((out / "plan.json").read_text())
    sim_json = json.loads((out / "sim.json").read_text())
    assert plan_json["method"] == "trajectotree" and plan_json["goal"] == 0.3
    for key in ("success", "status", "search_time_s", "solve_time_s", "total_time_s", "cost", "iterations"):
        assert summary["plan"][key] == plan_json[key], key
    assert summary["simulation"] == sim_json
    assert (out / "keyframes.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "forces.png").read_bytes()[:4] == b"\x89PNG"
    assert "<html" in (out / "playback.html").read_text()[:2000].lower()
    assert f"{plan_json['total_time_s']:.2f} s wall" in printed and str(out) in printed
    assert f"open {out / 'playback.html'} in a browser" in printed


def test_demo_rejects_a_goal_out_of_range(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "demo"), "--goal", "64"]) == 2
    assert "--goal = 64.0 is out of range" in capsys.readouterr().err
    assert not (tmp_path / "demo").exists()
