"""The `trajectotree` command. Each subcommand lives in its own module of this
package and exposes `register(subparsers)`; `main` adds those named in COMMANDS.

Exit codes: 0 success (a plan that did not converge is still a success of the
command, reported as "success": false), 2 invalid input, 1 unexpected error, 130
interrupted (Ctrl-C), 143 terminated (SIGTERM), 141 stdout closed by its reader (`| head`).
Either stop ends the command's worker processes (keyframes' segment workers, a sweep's
trials) before it exits; SIGKILL ends them too (trajectotree.planning.workers).
"""

from __future__ import annotations

import argparse
import atexit
import ctypes
import gc
import importlib
import os
import re
import signal
import sys
import threading

from trajectotree import __version__
from trajectotree.config import ConfigError

# Subcommand modules, in the order `--help` lists them.
COMMANDS = ("demo", "scene", "search", "plan", "simulate", "state", "sweep", "report")


# A token that starts with a minus sign and a digit (or ".digit") is a value, never an option:
# no option of this command looks like that (tests/cli/test_cli_input.py checks it).
NUMBER_LIKE = re.compile(r"-\.?\d")


class Parser(argparse.ArgumentParser):
    """argparse takes "-1e-1" or "-0.2,0@3" for an unknown option ("expected one argument"): its
    negative-number pattern (Python 3.11's) knows only "-1" and "-.5". Widened to every token
    NUMBER_LIKE matches (the pattern later Pythons' argparse uses); add_subparsers makes each
    subcommand's parser of this class too."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NUMBER_LIKE


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the main thread is: every cleanup that Ctrl-C runs (killing the
    segment workers, stopping a sweep's trials) runs for `kill` too, which would otherwise
    end this process at once and leave its children running."""


def _terminate(signum, frame):
    raise Terminated


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command's parser: with every subcommand, or with `command`'s alone (one of COMMANDS), which
    imports no other subcommand's module (their imports cost 0.15-0.27 s of a `plan`, issue 35)."""
    parser = Parser(
        prog="trajectotree",
        description="Plan, execute and evaluate multi-contact finger-gaiting manipulation "
        "with TrajectoTree (contact-sequence search + CITO on Drake).",
    )
    parser.add_argument("--version", action="version", version=f"trajectotree {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS if command is None else (command,):
        importlib.import_module(f"trajectotree.cli.{name}_cmd").register(subparsers)
    return parser


def named_command(argv: list[str]) -> str | None:
    """The subcommand `argv` names (its first token that is no option) when it is one of COMMANDS, else None."""
    named = next((a for a in argv if not a.startswith("-")), None)
    return named if named in COMMANDS else None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser(named_command(argv)).parse_args(argv)
    if not getattr(args, "resumes_collector", False):  # a command that does resumes it after its own start-up
        resume_collector()
    # Python lets only the main thread set a handler; main() run in another thread keeps the default.
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    try:
        return int(args.run(args) or 0)
    except ConfigError as e:  # invalid input: name the value and the valid range
        print(f"trajectotree {args.command}: error: {e}", file=sys.stderr)
        return 2
    except Terminated:
        print(f"trajectotree {args.command}: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print(f"trajectotree {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # whoever read stdout has gone (`| head`); the files are written by then
        # Python flushes stdout again at exit and would report that too: point it at /dev/null
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    finally:
        if in_main_thread:  # main() called from a program (the tests) leaves its handler as it was
            signal.signal(signal.SIGTERM, previous)


def console() -> None:
    """The `trajectotree` executable and `python -m trajectotree.cli`: main(), and the process ends with
    its exit code without the interpreter's teardown (end_without_teardown). Python's cyclic garbage collector
    is paused until the command's start-up is done (resume_collector): the imports, Drake's bindings and the
    scene allocate hundreds of thousands of objects that live as long as the process, and hardly any garbage,
    and the collector's passes over them cost a `plan` process 0.05-0.1 s (issue 35)."""
    gc.disable()
    code = main()
    end_without_teardown(code)
    sys.exit(code)


def resume_collector() -> None:
    """Resumes the garbage collector that console() paused, the objects allocated so far frozen (gc.freeze: its
    passes skip them from now on, and the segment workers forked later do not copy them on a pass); nothing
    where it runs (main() called by a program)."""
    if not gc.isenabled():
        gc.freeze()
        gc.enable()


def end_without_teardown(code: int) -> None:
    """Ends this process with `code` as Python's exit would, less the teardown of its modules and objects
    (Drake's plants, about 600 modules: 0.2-0.4 s of a `plan` process, issue 35), which the end of the
    process frees anyway. First what that exit runs before the teardown: the threads' exit (the kept segment
    pool shut down, its workers joined; other threads joined), the atexit handlers, stdout and stderr
    flushed, and the C library's buffers (IPOPT's output at print_level > 0). Returns, leaving it to
    Python's exit, where stdout cannot be flushed (its reader gone), which Python reports itself."""
    threading._shutdown()  # what Python's exit runs first: concurrent.futures' pools shut down, threads joined
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError:
        return
    ctypes.CDLL(None).fflush(None)  # every C stream (NULL)
    os._exit(code)


if __name__ == "__main__":
    console()
