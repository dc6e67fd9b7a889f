"""IPOPT's progress on a terminal: one line, rewritten in place, with the iteration, the
objective and the constraint violation, read from IPOPT's log while it solves. Shown only
when stderr is a terminal and the command does not print JSON."""

from __future__ import annotations

import re
import sys
import threading
from contextlib import contextmanager
from functools import partial
from typing import TextIO

# An iteration line of IPOPT's log: iter (r: restoration phase), objective, inf_pr, inf_du, ...
ITERATION_LINE = re.compile(r"^\s*(\d+)r?\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s")
POLL_S = 0.2  # s, how often the log is read


def format_iteration(line: str) -> str | None:
    """'IPOPT iteration 12: objective 1.23e+02, constraint violation 4.5e-03' of an
    iteration line of IPOPT's log, None for any other line."""
    m = ITERATION_LINE.match(line)
    if not m:
        return None
    return (
        f"IPOPT iteration {int(m.group(1))}: objective {float(m.group(2)):.3e}, "
        f"constraint violation {float(m.group(3)):.1e}"
    )


def _follow(log_path: str, stream: TextIO, stop: threading.Event) -> None:
    """Shows the latest iteration line of the log until `stop` is set (then reads it once more)."""
    pending = ""
    with open(log_path, errors="replace") as log:
        while True:
            stopping = stop.wait(POLL_S)
            pending += log.read()
            *lines, pending = pending.split("\n")
            shown = [text for text in map(format_iteration, lines) if text]
            if shown:
                stream.write("\r\033[K  " + shown[-1])
                stream.flush()
            if stopping:
                return


@contextmanager
def _show_log(stream: TextIO, log_path: str):
    stop = threading.Event()
    thread = threading.Thread(target=_follow, args=(log_path, stream, stop), daemon=True, name="ipopt-progress")
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        stream.write("\r\033[K")  # the summary printed next replaces the progress line
        stream.flush()


def ipopt_progress(enabled: bool, stream: TextIO = sys.stderr):
    """The log observer (cito.solve.LogObserver) that shows each IPOPT solve's progress on
    `stream`, for planners.plan(log_observer=); None when not `enabled`."""
    return partial(_show_log, stream) if enabled else None


def wanted(args) -> bool:
    """Progress is for people watching a terminal: not with --json, not into a file or pipe."""
    return sys.stderr.isatty() and not getattr(args, "json", False)
