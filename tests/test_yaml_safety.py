"""YAML files that would cost a user's memory, time or a traceback (issue "Faults a user hit", item 3):
a "billion laughs" config of 8 levels of 9 aliases, 100,000 nested brackets, a 50 MB file, a
duplicated key, and the same in a hand description. Each is refused by typed_yaml.read_yaml with one
line naming the file, the place and the limit (CLI exit 2, nothing written), and no message repeats
more than 80 characters of a value."""

import resource
import subprocess
import sys
import tracemalloc
from pathlib import Path

import pytest

from trajectotree.cli import main
from trajectotree.config import HAND_NAMES, Config, ConfigError, load_config
from trajectotree.scene.hand import HandError, hand_file
from trajectotree.typed_yaml import MAX_YAML_BYTES, MAX_YAML_DEPTH, YamlError, read_yaml

REPO = Path(__file__).resolve().parents[1]
PLANAR_HAND_SDF = REPO / "models" / "planar_hand.sdf"
REFUSED = "anchors (&), aliases (*) and merge keys are refused: write each value out"
TOO_BIG = f"valid: at most {MAX_YAML_BYTES} bytes (64 KiB), 25 times the largest config or hand description"


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def written(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def billion_laughs(path: Path) -> Path:
    """The tester's file: under goal: theta:, 8 levels of 9 aliases each of the level before (9^9 strings)."""
    lines = ["goal:", "  theta:", "    - &a0 [" + ", ".join(["lol"] * 9) + "]"]
    lines += [f"    - &a{k} [" + ", ".join([f"*a{k - 1}"] * 9) + "]" for k in range(1, 9)]
    return written(path, "\n".join(lines) + "\n")


def nested_brackets(path: Path, depth: int) -> Path:
    return written(path, "[" * depth + "]" * depth)


def sparse_file(path: Path, size: int) -> Path:
    with path.open("wb") as file:
        file.truncate(size)  # a hole: no disk written, and NUL bytes that a parser would refuse otherwise
    return path


def hand_yaml(path: Path, fingers: str) -> Path:
    """A description of the project's four-finger hand with the `fingers` entries given."""
    return written(path, f"model: {PLANAR_HAND_SDF}\nfingers:\n{fingers}")


FINGERS = [f"  - {{joints: [finger{i}_joint1, finger{i}_joint2], tip: finger{i}_tip}}\n" for i in range(4)]

# (file name, how to write it, what the message says after the file's name)
CONFIG_REPRODUCERS = [
    ("laughs.yaml", billion_laughs, f"has an anchor &a0 at line 3, column 7; {REFUSED}"),
    ("brackets.yaml", lambda p: nested_brackets(p, 100_000), f"is 200000 bytes; {TOO_BIG}"),
    (
        "deep.yaml",  # 60 kB: within the size limit, so the depth limit refuses it
        lambda p: nested_brackets(p, 30_000),
        f"nests mappings and lists deeper than 32 levels at line 1, column 33; valid: at most {MAX_YAML_DEPTH} levels",
    ),
    ("huge.yaml", lambda p: sparse_file(p, 50 * 2**20), f"is 52428800 bytes; {TOO_BIG}"),
    (
        "twice.yaml",
        lambda p: written(p, "scene:\n  box_mass: 0.05\n  box_mass: 0.08\n"),
        "has key 'box_mass' twice in one mapping, at line 2, column 3 and line 3, column 3; give each key once",
    ),
]
HAND_REPRODUCERS = [
    (
        lambda p: hand_yaml(p, "  - &f " + FINGERS[0][4:] + "  - *f\n  - *f\n  - *f\n"),
        f"has an anchor &f at line 3, column 5; {REFUSED}",
    ),
    (
        lambda p: hand_yaml(p, "".join(FINGERS[:3]) + FINGERS[3].replace("}", ", tip: finger0_tip}")),
        "has key 'tip' twice in one mapping, at line 6, column 48 and line 6, column 66; give each key once",
    ),
]
COMMANDS = [["plan", "--goal", "1", "--out", "out"], ["search", "--goal", "1", "--figure", "out.png"]]


def in_tmp(command: list[str], tmp_path: Path) -> list[str]:
    return [str(tmp_path / a) if a in ("out", "out.png") else a for a in command]


@pytest.mark.parametrize("name, write, message", CONFIG_REPRODUCERS, ids=[r[0] for r in CONFIG_REPRODUCERS])
@pytest.mark.parametrize("command", COMMANDS, ids=["plan", "search"])
def test_each_config_reproducer_exits_2_with_one_line_and_writes_nothing(
    tmp_path, capsys, name, write, message, command
):
    path = write(tmp_path / name)
    assert main([*in_tmp(command, tmp_path), "--config", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"trajectotree {command[0]}: error: config file {str(path)!r} {message}\n"
    assert captured.out == "" and listing(tmp_path) == [name]


@pytest.mark.parametrize("write, message", HAND_REPRODUCERS, ids=["aliases", "duplicate"])
@pytest.mark.parametrize("command", COMMANDS, ids=["plan", "search"])
def test_each_hand_reproducer_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, write, message, command):
    path = write(tmp_path / "hand.yaml")
    assert main([*in_tmp(command, tmp_path), "--hand", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"trajectotree {command[0]}: error: hand {path}: {message}\n"
    assert captured.out == "" and listing(tmp_path) == ["hand.yaml"]


def test_the_hand_file_reproducers_read_right_without_the_fault(tmp_path):
    """The two hand files above differ from a good one only by the fault: the same fingers, read."""
    hand = hand_file(str(hand_yaml(tmp_path / "good.yaml", "".join(FINGERS))))
    assert [f.tip for f in hand.fingers] == [f"finger{i}_tip" for i in range(4)]


def test_a_billion_laughs_is_refused_by_a_process_of_2_gib(tmp_path):
    """The CLI in a process whose address space is capped at 2 GiB (the file took 9.4 GB before):
    exit 2, one line, no traceback, no plan folder."""
    path = billion_laughs(tmp_path / "laughs.yaml")

    def cap_memory():
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))

    run = subprocess.run(
        [sys.executable, "-m", "trajectotree.cli", "plan", "--config", str(path), "--goal", "1"]
        + ["--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        preexec_fn=cap_memory,
        timeout=120,
    )
    assert run.returncode == 2, run.stderr[-2000:]
    assert (
        run.stderr
        == f"trajectotree plan: error: config file {str(path)!r} has an anchor &a0 at line 3, column 7; {REFUSED}\n"
    )
    assert listing(tmp_path) == ["laughs.yaml"]


@pytest.mark.parametrize(
    "write",
    [billion_laughs, lambda p: sparse_file(p, 50 * 2**20)],
    ids=["laughs", "50 MB"],
)
def test_a_refused_file_costs_under_a_mebibyte(tmp_path, write):
    """Python's allocations while refusing: the 50 MB file is never read, the aliases never expanded
    (each costs under 100 KiB; 30,000 nested brackets cost about 1 MiB, PyYAML's scanner looking
    ahead along their line, which MAX_YAML_BYTES bounds)."""
    path = write(tmp_path / "c.yaml")
    tracemalloc.start()
    try:
        with pytest.raises(ConfigError):
            load_config(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20, peak


def test_the_limits_are_inclusive(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("{}\n#" + "x" * (MAX_YAML_BYTES - 5) + "\n")  # the defaults, in exactly MAX_YAML_BYTES bytes
    assert path.stat().st_size == MAX_YAML_BYTES and load_config(path) == Config()
    path.write_text("{}\n#" + "x" * (MAX_YAML_BYTES - 4) + "\n")
    with pytest.raises(ConfigError, match=f"is {MAX_YAML_BYTES + 1} bytes; valid: at most {MAX_YAML_BYTES} bytes"):
        load_config(path)
    nested = read_yaml(nested_brackets(path, MAX_YAML_DEPTH))
    for _ in range(MAX_YAML_DEPTH - 1):
        (nested,) = nested
    assert nested == []
    with pytest.raises(YamlError, match=f"deeper than 32 levels at line 1, column {MAX_YAML_DEPTH + 1}"):
        read_yaml(nested_brackets(path, MAX_YAML_DEPTH + 1))


@pytest.mark.parametrize(
    "text, message",
    [
        ("scene:\n  box_mass: *m\n", f"has an alias *m at line 2, column 13; {REFUSED}"),
        ("<<: {scene: {}}\n", "has a merge key << at line 1, column 1; merge keys, anchors"),
        ("scene:\n  1: 0.05\n", "has key 1 at line 2, column 3, which is not a name; valid keys: names (text)"),
        ("? [scene]\n: {}\n", "has key ['scene'] at line 1, column 3, which is not a name"),
        (
            "scene:\n  box_mass: " + "1" * 5000 + "\n",
            f"has an integer of 5000 characters at line 2, column 13; valid: at most {sys.get_int_max_str_digits()}",
        ),
        ("scene: [1, 2\n", "is not valid YAML: while parsing a flow sequence: expected ',' or ']', but got"),
        (
            "scene: {}\n---\ngoal: {}\n",
            "is not valid YAML: expected a single document in the stream: but found another",
        ),
        ("scene:\n  box_mass: !Kilo 5\n", "is not valid YAML: could not determine a constructor for the tag '!Kilo'"),
        (
            "scene:\n  box_mass: 0.0\x005\n",
            "is not valid YAML: character #x0000 at line 2, column 16: special characters",
        ),
    ],
)
def test_what_yaml_allows_beyond_configs_is_one_line_naming_the_place(tmp_path, text, message):
    """These raised AttributeError or ValueError tracebacks, or took a tag, before."""
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert str(error.value).startswith(f"config file {str(path)!r} {message}") and "\n" not in str(error.value)


def test_long_values_are_cut_to_80_characters_in_messages(tmp_path):
    error = ConfigError(field="scene.box_mass", value="x" * 1000, valid="(0, 3.22] kg")
    assert str(error) == f"scene.box_mass = '{'x' * 79}... (1002 characters) is out of range; valid range: (0, 3.22] kg"
    masses = [0.05] * 10_000  # a list for a number: Drake's typed loader refuses it, naming the key
    path = tmp_path / "c.yaml"
    path.write_text(f"scene:\n  box_mass: {masses}\n")
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert f"scene.box_mass = {repr(masses)[:80]}... ({len(repr(masses))} characters): " in str(error.value)
    assert len(str(error.value)) < 500
    path.write_text(f"model: {'x' * 20_000}.txt\nfingers: []\n")
    with pytest.raises(HandError) as error:
        hand_file(str(path))
    assert str(error.value) == f"hand {path}: model '{'x' * 79}... (20006 characters) is not an SDF or URDF file"


def test_every_yaml_file_of_the_project_reads_within_the_limits():
    """The built-in hands, configs/ and the tests' configs: no anchors, duplicates or deep nesting."""
    files = sorted([*REPO.glob("models/*.yaml"), *REPO.glob("configs/*.yaml"), *REPO.glob("tests/**/*.yaml")])
    assert len(files) >= 6
    for path in files:
        assert isinstance(read_yaml(path), dict), path
    assert [len(hand_file(name).fingers) for name in HAND_NAMES] == [4, 3, 5]
    assert load_config(REPO / "configs" / "paper.yaml").search.friction_safety == 1.0


def test_a_config_name_too_long_to_look_up_is_refused_naming_it(tmp_path, capsys):
    """A name over the file system's 255 bytes: Path.is_dir raised OSError (exit 1, a traceback) before."""
    path = tmp_path / ("c" * 300 + ".yaml")
    assert main(["plan", "--goal", "1", "--config", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err == f"trajectotree plan: error: config file {str(path)!r} cannot be read: File name too long\n"
    assert listing(tmp_path) == []
