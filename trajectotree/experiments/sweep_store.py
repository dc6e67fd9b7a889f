"""A sweep's directory (layout: trajectotree.experiments.sweep): the manifest check, the lock,
reading finished trials (moving corrupt ones aside) and storing new ones atomically.
Only the sweep process writes here; trials run elsewhere and return their files as bytes."""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from trajectotree import __version__
from trajectotree.config import ConfigError
from trajectotree.experiments.trial import ROW_FILE, TrialOutcome
from trajectotree.io import LOCK_FILE, PLAN_NPZ, SIM_NPZ, folder_lock, npz_problem, write_bytes_atomic

MANIFEST_FILE = "manifest.json"
TRIALS_DIR = "trials"
ROWS_FILE = "trials.jsonl"
TMP_PREFIX = ".tmp-"
CORRUPT_DIR = "corrupt"
# Manifest keys that may change between runs of one sweep: not part of a trial's identity.
RUN_SETTINGS = ("goal_values", "version", "time_limit_s")


class CorruptTrialError(ConfigError):
    """A finished trial's trial.json cannot be read (the message names the file)."""

    def __init__(self, path: Path, reason: str):
        super().__init__(f"{str(path)!r} is unreadable ({reason}); rerun the sweep to recompute that trial")
        self.path, self.reason = path, reason


# Config sections that only executions read: a planning-only sweep's trials do not depend on
# them (its executions are run later, with the controller settings given then).
EXECUTION_SECTIONS = ("controller", "sim")


def _identity(manifest: dict) -> dict:
    """The manifest's fields that decide its trials (nested as in the manifest)."""
    identity = {k: v for k, v in manifest.items() if k not in RUN_SETTINGS}
    if not manifest.get("simulate"):
        identity["config"] = {k: v for k, v in manifest.get("config", {}).items() if k not in EXECUTION_SECTIONS}
    return identity


def _brief(value) -> str:
    """A value as a difference names it: a whole section by its size (not its every field)."""
    return f"a section of {len(value)} settings" if isinstance(value, dict) else repr(value)


def _differences(old: dict, new: dict, prefix: str = "") -> list[str]:
    """'name: old there, new now' for each differing field, descending into sections both sides have; a section
    one side lacks is one difference (a sweep that simulates records the controller's settings, one that does not
    omits them: its ~60 fields once listed one by one)."""
    differences = []
    for key in sorted(set(old) | set(new)):
        a, b, name = old.get(key), new.get(key), f"{prefix}{key}"
        if isinstance(a, dict) and isinstance(b, dict):
            differences += _differences(a, b, f"{name}.")
        elif a != b:
            differences.append(f"{name}: {_brief(a)} there, {_brief(b)} now")
    return differences


def _manifest_differences(old: dict, new: dict) -> list[str]:
    """'name: old there, new now' for each differing argument or config field."""
    return _differences(_identity(old), _identity(new))


def _made_by_a_sweep(path: Path) -> bool:
    """What a sweep starting in a folder makes before its manifest is in place: the lock file,
    write_bytes_atomic's temporary file of the manifest, or (before the manifest came first)
    an empty trials/; a sweep killed then leaves a folder the next one may still take."""
    if path.name == TRIALS_DIR:
        return path.is_dir() and not any(path.iterdir())
    return path.name == LOCK_FILE or (path.name.startswith(f".{MANIFEST_FILE}.") and path.name.endswith(".tmp"))


def check_manifest(out_dir: Path, spec, locked: bool = True) -> bool:
    """True when out_dir already holds this sweep, False when it holds none;
    raises ConfigError when it holds a different one (nothing is touched).
    Judged for certain only by the holder of the folder's lock (sweep_lock). Without it
    (locked False: the early check, which refuses before anything is written) a folder
    with a lock file but no manifest is left to the lock: another sweep may be starting
    there this instant, and its lock, not its half-made folder, is what to report."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--out {str(out_dir)!r} is an existing file, not a folder; give a sweep directory")
    path = out_dir / MANIFEST_FILE
    if not path.exists():
        if not locked and (out_dir / LOCK_FILE).exists():
            return False
        if out_dir.is_dir() and any(not _made_by_a_sweep(p) for p in out_dir.iterdir()):
            raise ConfigError(
                f"--out {str(out_dir)!r} is a non-empty directory without {MANIFEST_FILE}; "
                "give a new or empty directory, or the directory of the sweep to resume"
            )
        return False
    try:
        old = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ConfigError(f"{str(path)!r} is not a readable sweep manifest: {e}") from None
    diffs = _manifest_differences(old, spec.manifest())
    if diffs:
        raise ConfigError(
            f"{str(out_dir)!r} holds a sweep with different arguments ({'; '.join(diffs)}); "
            "rerun with the same arguments to resume it, or choose another --out"
        )
    return True


def prepare_dir(out_dir: Path, spec) -> list[str]:
    """Creates the sweep directory (or reopens it), removes leftovers of a killed run and
    moves corrupt trials aside (they are recomputed); returns a message per moved trial.
    The caller holds the directory's lock (sweep_lock)."""
    exists = check_manifest(out_dir, spec)
    manifest = dict(spec.manifest(), version=__version__)
    if exists:  # keep what the sweep is; record this run's time limit
        manifest = dict(json.loads((out_dir / MANIFEST_FILE).read_text()), time_limit_s=spec.time_limit_s)
    # The manifest first: a sweep killed before it is written leaves a folder the next one still accepts.
    write_bytes_atomic(out_dir / MANIFEST_FILE, json.dumps(manifest, indent=2).encode())
    (out_dir / TRIALS_DIR).mkdir(parents=True, exist_ok=True)
    for leftover in (out_dir / TRIALS_DIR).glob(f"{TMP_PREFIX}*"):  # incl. killed trials' scratch folders
        shutil.rmtree(leftover) if leftover.is_dir() else leftover.unlink()
    for leftover in out_dir.glob(".*.tmp"):  # write_bytes_atomic's temporary files
        leftover.unlink()
    return set_aside_corrupt_trials(out_dir)


@contextmanager
def sweep_lock(out_dir: Path) -> Iterator[None]:
    """Holds OUT/.lock while the sweep runs (io.folder_lock, which `plan`, `simulate` and `demo`
    take too); ConfigError naming the holder's pid if another process holds it. The file stays,
    emptied, on release: a pid found in it on taking it belonged to a sweep that died (its stale
    lock is taken over, with a note on stderr)."""
    with folder_lock(out_dir, "--out", "sweep", keep=True):
        yield


def read_row(trial_dir: Path) -> dict:
    """A finished trial's row; CorruptTrialError naming the file when it is unreadable."""
    path = trial_dir / ROW_FILE
    try:
        row = json.loads(path.read_text())
        if not isinstance(row, dict) or row.get("key") != trial_dir.name or not isinstance(row.get("method"), str):
            raise ValueError(f"not the row of trial {trial_dir.name!r}")
    except (OSError, UnicodeDecodeError, ValueError) as e:  # JSONDecodeError is a ValueError
        raise CorruptTrialError(path, f"{type(e).__name__}: {e}") from None
    return row


def check_trial(trial_dir: Path) -> dict:
    """A finished trial's row, once its array files read back whole: plan.npz (a row without
    an error has one, unless its plan_arrays is false), sim.npz (a simulated row has one) and any other .npz there.
    CorruptTrialError naming the first unreadable file."""
    row = read_row(trial_dir)
    # a trial in space whose search found no contact sequence has no plan.npz: its row says so (plan_arrays)
    planned = row.get("error") is None and row.get("plan_arrays", True)
    promised = ([PLAN_NPZ] if planned else []) + ([SIM_NPZ] if row.get("simulated") else [])
    for name in sorted(set(promised) | {p.name for p in trial_dir.glob("*.npz")}):
        problem = npz_problem(trial_dir / name)
        if problem:
            raise CorruptTrialError(trial_dir / name, problem)
    return row


def _finished_trial_dirs(out_dir: Path) -> list[Path]:
    trials = out_dir / TRIALS_DIR
    if not trials.is_dir():
        return []
    return [
        d
        for d in sorted(trials.iterdir())
        if d.is_dir() and not d.name.startswith(TMP_PREFIX) and (d / ROW_FILE).is_file()
    ]


def read_rows(out_dir: str | Path) -> list[dict]:
    """The rows of every finished trial, in goal-major order (trial directories are
    authoritative; trials.jsonl is a convenience copy). CorruptTrialError names an unreadable one."""
    return [read_row(d) for d in _finished_trial_dirs(Path(out_dir))]


def set_aside_corrupt_trials(out_dir: Path) -> list[str]:
    """Moves each trial whose trial.json or array files are unreadable (check_trial) to
    OUT/corrupt/ (kept for inspection), so the sweep recomputes it; returns one message per
    trial moved."""
    messages = []
    for trial_dir in _finished_trial_dirs(out_dir):
        try:
            check_trial(trial_dir)
        except CorruptTrialError as e:
            target = out_dir / CORRUPT_DIR / f"{trial_dir.name}-{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}"
            target.parent.mkdir(exist_ok=True)
            os.replace(trial_dir, target)
            messages.append(
                f"{str(e.path)!r} was unreadable ({e.reason}); moved the trial to {str(target)!r}; it is recomputed"
            )
    return messages


def write_rows_file(out_dir: Path) -> None:
    rows = read_rows(out_dir)
    write_bytes_atomic(out_dir / ROWS_FILE, "".join(json.dumps(r) + "\n" for r in rows).encode())


def store_trial(out_dir: Path, outcome: TrialOutcome) -> None:
    """Writes the trial's directory under a temporary name, then renames it into place,
    and appends its row to trials.jsonl."""
    key = outcome.row["key"]
    final = out_dir / TRIALS_DIR / key
    tmp = out_dir / TRIALS_DIR / f"{TMP_PREFIX}{key}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    for name, data in outcome.files.items():
        with open(tmp / name, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    if final.exists():  # a retried trial replaces its error record
        shutil.rmtree(final)
    os.replace(tmp, final)
    with open(out_dir / ROWS_FILE, "a") as f:
        f.write(json.dumps(outcome.row) + "\n")
