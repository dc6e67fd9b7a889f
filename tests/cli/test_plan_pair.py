"""A plan folder's files belong together (issue "Faults a user hit", item 8): plan.json records the
digest of plan.npz's arrays and the JSON types of its values are checked; `plan`, `simulate` and
`demo` hold the folder's lock while they work in it; a new plan removes the old plan's run.
Real plans (tests/conftest.py's tiny_plan and one more of another goal) and real processes."""

import json
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY_PLAN

from trajectotree.cli import main
from trajectotree.config import ConfigError
from trajectotree.io import ARRAYS_DIGEST, LOCK_FILE, folder_lock, load_plan, load_sim, read_plan_files

# The other plan of a mix-up: the tiny plan's scene and segments, another goal (0.1 rad there).
OTHER_GOAL = ["--goal", "0.2", "--segments", "1"]


def names(folder: Path) -> list[str]:
    """Every entry of `folder`, hidden ones too."""
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture(scope="module")
def other_plan(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("other_plan") / "plan"
    assert main(["plan", *OTHER_GOAL, "--out", str(out)]) == 0
    return out


def mixed(tiny_plan: Path, other_plan: Path, to: Path, drop_digest: bool = False) -> Path:
    """tiny_plan's plan.json beside other_plan's plan.npz (without the digest: as older plans were saved)."""
    to.mkdir()
    data = json.loads((tiny_plan / "plan.json").read_text())
    if drop_digest:
        del data[ARRAYS_DIGEST]
    (to / "plan.json").write_text(json.dumps(data))
    shutil.copy(other_plan / "plan.npz", to / "plan.npz")
    return to


def test_simulate_refuses_a_plan_json_beside_another_plans_npz_naming_both(tiny_plan, other_plan, tmp_path, capsys):
    folder = mixed(tiny_plan, other_plan, tmp_path / "mixed")
    capsys.readouterr()
    assert main(["simulate", str(folder), "--forces", str(tmp_path / "forces.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(
        f"trajectotree simulate: error: {str(folder / 'plan.npz')!r} does not belong to the plan "
        f"{str(folder / 'plan.json')!r} describes: the SHA-256 of its arrays is "
    ), err
    assert "(plan.npz: 13 knots, ending at orientation +0.2000 rad; plan.json: goal +0.1000 rad, 2 nodes)" in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert names(folder) == ["plan.json", "plan.npz"] and not (tmp_path / "forces.png").exists()
    with pytest.raises(ConfigError, match="does not belong to the plan"):  # the API reads it alike
        load_plan(folder)


def test_an_older_pair_without_the_digest_is_checked_for_what_it_can_and_says_so(tiny_plan, other_plan, tmp_path):
    older = tmp_path / "older"
    older.mkdir()
    data = json.loads((tiny_plan / "plan.json").read_text())
    del data[ARRAYS_DIGEST]
    (older / "plan.json").write_text(json.dumps(data))
    shutil.copy(tiny_plan / "plan.npz", older / "plan.npz")
    note = read_plan_files(older).unverified
    assert note == (
        f"{str(older / 'plan.json')!r} records no {ARRAYS_DIGEST} (saved before plans did), so only that "
        "plan.npz's knots, joints and final orientation fit it was checked"
    )
    assert read_plan_files(tiny_plan).unverified is None
    folder = mixed(tiny_plan, other_plan, tmp_path / "mixed", drop_digest=True)
    with pytest.raises(ConfigError) as refused:
        read_plan_files(folder)
    assert str(refused.value) == (
        f"{str(folder / 'plan.npz')!r} does not belong to the plan {str(folder / 'plan.json')!r} describes: it ends "
        "at orientation +0.2000 rad, 0.1000 rad from plan.json's goal +0.1000 rad (a successful plan ends within "
        "0.001 rad of its goal)"
    )


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("success", "yes", '"yes" is a string; it must be a JSON boolean (true or false)'),
        ("goal", "0.1", '"0.1" is a string; it must be a number'),
        ("iterations", 3.5, "3.5 is a number; it must be an integer"),
        ("cost", True, "true is a JSON boolean (true or false); it must be a number or null"),
    ],
)
def test_plan_json_values_of_the_wrong_json_type_are_refused_naming_the_key(
    tiny_plan, tmp_path, capsys, key, value, expected
):
    folder = tmp_path / "plan"
    shutil.copytree(tiny_plan, folder)
    data = json.loads((folder / "plan.json").read_text())
    data[key] = value
    (folder / "plan.json").write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["simulate", str(folder)]) == 2
    assert capsys.readouterr().err == (
        f"trajectotree simulate: error: {str(folder / 'plan.json')!r}: {key} = {expected}\n"
    )
    assert names(folder) == ["plan.json", "plan.npz"]
    with pytest.raises(ConfigError, match=f"{key} = "):
        load_plan(folder)


def test_nested_and_sim_json_types_are_checked_too(tiny_plan, tmp_path):
    folder = tmp_path / "plan"
    shutil.copytree(tiny_plan, folder)
    data = json.loads((folder / "plan.json").read_text())
    data["search"]["success"] = 1
    (folder / "plan.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"search\.success = 1 is an integer; it must be a JSON boolean"):
        load_plan(folder)
    sim = {
        "mae_x": 0.0, "mae_y": 0.0, "mae_theta": 0.0, "final_error": [0.0, 0.0, 0.0], "dropped": "no",
        "drop_time_s": None, "sim_time_s": 1.0,
    }  # fmt: skip
    (folder / "sim.json").write_text(json.dumps(sim))
    np.savez(folder / "sim.npz", t=np.zeros(2))
    with pytest.raises(ConfigError, match=r"sim\.json': dropped = \"no\" is a string; it must be a JSON boolean"):
        load_sim(folder)


# A process that holds a folder's lock as the command named in argv[2] does, until it is killed.
HOLD_LOCK = """
import sys, time
from trajectotree.io import folder_lock
with folder_lock(sys.argv[1], "--out", sys.argv[2]):
    print("locked", flush=True)
    time.sleep(600)
"""


def hold_lock(folder: Path, holder: str) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, "-c", HOLD_LOCK, str(folder), holder], stdout=subprocess.PIPE, text=True
    )
    assert process.stdout.readline() == "locked\n"
    return process


def release(process: subprocess.Popen) -> None:
    process.kill()
    process.wait()
    process.stdout.close()


def test_a_second_command_on_a_folder_in_use_exits_2_and_a_dead_holders_lock_is_taken_over(tiny_plan, tmp_path, capsys):
    folder = tmp_path / "plan"
    shutil.copytree(tiny_plan, folder)
    before = {name: (folder / name).read_bytes() for name in ("plan.json", "plan.npz")}
    holder = hold_lock(folder, "trajectotree simulate")
    try:
        capsys.readouterr()
        for command in (["plan", *TINY_PLAN, "--out"], ["simulate"], ["demo", *TINY_PLAN, "--out"]):
            assert main([*command, str(folder)]) == 2, command
            option = "PLAN_DIR" if command == ["simulate"] else "--out"
            assert capsys.readouterr().err == (
                f"trajectotree {command[0]}: error: {option} {str(folder)!r} is in use by another trajectotree "
                f"simulate (process pid {holder.pid} on {socket.gethostname()}; lock "
                f"file {str(folder / LOCK_FILE)!r}); wait for it to finish or stop it, or choose another {option}\n"
            )
        assert names(folder) == [LOCK_FILE, "plan.json", "plan.npz"]  # the holder's lock alone: nothing written
        assert {name: (folder / name).read_bytes() for name in before} == before
    finally:
        release(holder)
    assert f"pid {holder.pid} " in (folder / LOCK_FILE).read_text()  # the dead holder's stale lock
    assert main(["plan", *TINY_PLAN, "--out", str(folder)]) == 0
    assert f"taking over the stale lock of process pid {holder.pid} " in capsys.readouterr().err
    assert names(folder) == ["plan.json", "plan.npz"]  # the lock is removed on release


def test_a_new_plan_removes_the_old_plans_run(tiny_plan, tmp_path, capsys):
    folder = tmp_path / "plan"
    shutil.copytree(tiny_plan, folder)
    (folder / "sim.json").write_text("{}")
    (folder / "sim.npz").write_bytes(b"the old plan's run")
    capsys.readouterr()
    assert main(["plan", *OTHER_GOAL, "--out", str(folder)]) == 0
    assert f"removed sim.json, sim.npz from {folder}: they belonged to the plan this one replaces" in (
        capsys.readouterr().err
    )
    assert names(folder) == ["plan.json", "plan.npz"]
    assert load_plan(folder).goal == 0.2


def test_the_lock_removes_the_folders_it_made_when_nothing_was_written(tmp_path):
    made = tmp_path / "a" / "b"
    with pytest.raises(ConfigError, match="refused inside"), folder_lock(made, "--out", "trajectotree plan"):
        assert names(made) == [LOCK_FILE]
        raise ConfigError("refused inside")
    assert names(tmp_path) == []
    with folder_lock(made, "--out", "trajectotree plan"):
        (made / "plan.json").write_text("{}")
    assert names(made) == ["plan.json"]  # kept, with what was written; the lock file gone
    with folder_lock(made, "--out", "sweep", keep=True):
        pass
    assert (made / LOCK_FILE).read_text() == ""  # a sweep's folder keeps its lock file, emptied
    with pytest.raises(ConfigError, match=r"PLAN_DIR '.*nothing' is not a directory"):
        with folder_lock(tmp_path / "nothing", "PLAN_DIR", "trajectotree simulate", create=False):
            pass
    assert not (tmp_path / "nothing").exists()
