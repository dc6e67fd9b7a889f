"""The CLI's stdout closed by its reader, and names longer than the file system allows."""

from __future__ import annotations

import subprocess
import sys


def test_stdout_closed_by_its_reader_ends_quietly_with_141(tmp_path):
    # `trajectotree search ... | head -c 1` closes the pipe before the JSON is printed
    command = [sys.executable, "-m", "trajectotree.cli", "search", "--goal", "0.3", "--json"]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    child.stdout.close()
    stderr = child.stderr.read().decode()
    assert child.wait(timeout=120) == 141
    assert "Traceback" not in stderr and "BrokenPipe" not in stderr
    assert list(tmp_path.iterdir()) == []


def test_a_hand_file_name_longer_than_name_max_is_refused_as_missing(tmp_path, capsys):
    from trajectotree.cli import main

    name = "h" * 300 + ".yaml"
    assert main(["search", "--goal", "0.3", "--hand", name]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("trajectotree search: error: --hand (scene.hand) = 'hhhh") and "does not exist" in err
    assert "(307 characters)" in err  # its repr, quotes included, cut to 80 and len(err.splitlines()) == 1
