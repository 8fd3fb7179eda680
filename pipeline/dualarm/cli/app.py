"""The ``dualarm`` Typer app and its groups, the consoles, and how a command ends.

One line and exit 2 for a user's mistake, 130 or 143 on a signal.
"""

from __future__ import annotations

import functools
import importlib
import signal
import sys
import threading
from collections.abc import Callable
from typing import Any

import typer
from rich.console import Console
from rich.status import Status
from typer.core import TyperGroup

from dualarm.errors import DualarmError, StageError, Terminated, excerpt

#: Exit codes of every command.
EXIT_CODES = {
    "complete": 0,
    "violated": 3,
    "failed": 1,
    "user error": 2,
    "interrupted (SIGINT)": 130,
    "terminated (SIGTERM)": 143,
}

#: The exceptions of the click that Typer uses (its own copy since Typer 0.23).
_click = importlib.import_module(typer.BadParameter.__module__)


class _Commands(TyperGroup):
    """The app's command group: a usage error (an unknown option, a missing argument, ...) is one line.

    Click prints four (the usage, a hint, a blank line, the error); the usage is one ``--help`` away.
    """

    def main(self, *args: Any, **kwargs: Any) -> Any:  # Click's: (args, prog_name, complete_var, standalone_mode, ...)
        if not kwargs.get("standalone_mode", True) or len(args) > 3:  # a caller handling Click's exceptions itself
            return super().main(*args, **kwargs)
        try:  # no command returns a value: what comes back is an exit code (typer.Exit's) or None
            code = super().main(*args, **{**kwargs, "standalone_mode": False})
        except getattr(_click, "NoArgsIsHelpError", ()) as exc:  # a group called alone: its help
            exc.show()
            sys.exit(exc.exit_code)
        except _click.ClickException as exc:
            where = exc.ctx.command_path if isinstance(exc, _click.UsageError) and exc.ctx is not None else "dualarm"
            err.print(
                excerpt(f"error: {where}: {exc.format_message().rstrip('.')} (see '{where} --help')", MAX_LINE),
                markup=False,
                soft_wrap=True,
            )
            sys.exit(exc.exit_code)
        except getattr(_click, "Abort", ()):  # typer 0.29's own click has none; an unexpected error then propagates
            err.print("aborted", markup=False)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(
    cls=_Commands,
    name="dualarm",
    help="Humanoid dual-arm motion papers as runnable, recorded, repeatable experiments.\n\nExit codes: "
    + ", ".join(f"{code} {what}" for what, code in EXIT_CODES.items())
    + ".",
    no_args_is_help=True,
    rich_markup_mode=None,  # help as written: rich markup would eat "[s]", "[rad]", ...
    add_completion=False,
    pretty_exceptions_enable=False,
)
robot_app = typer.Typer(help="Inspect and verify robot descriptions.", no_args_is_help=True)
app.add_typer(robot_app, name="robot")
bench_app = typer.Typer(help="Measure speed as ratios against peers run in the same process.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")
ik_app = typer.Typer(help="Inverse kinematics of single poses.", no_args_is_help=True)
app.add_typer(ik_app, name="ik")
task_app = typer.Typer(help="Author and validate task files.", no_args_is_help=True)
app.add_typer(task_app, name="task")
# Text is printed as it is: no markup, no emoji codes (":robot:" stays), in messages and table cells.
out = Console(
    highlight=False, markup=False, emoji=False, width=None if sys.stdout.isatty() else 160
)  # tables unwrapped in pipes and files
err = Console(stderr=True, highlight=False, markup=False, emoji=False)
#: The longest line an error prints [characters] (a message quotes a user's string in ~80).
MAX_LINE = 400


def user_errors(func: Callable) -> Callable:
    """Turn a DualarmError into one line on stderr and exit code 2.

    A StageError from a recorded run (a run that failed on valid input, kept as failed) into
    ``verdict: failed``, the error and where the run is kept, and exit code 1.

    Ctrl-C (SIGINT) and SIGTERM during the command end it with one line and exit code 130 or 143
    (:data:`EXIT_CODES`); a run being recorded is kept as failed (:func:`_catch_signals`).
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        received = _received
        received.clear()
        previous = _catch_signals(received)
        try:
            return func(*args, **kwargs)
        except StageError as exc:  # valid input, but a stage could not produce its output: the run failed
            if exc.run_directory is None:  # refused before any run was recorded: the input cannot be run
                err.print(excerpt(f"error: {exc}", MAX_LINE), markup=False, soft_wrap=True)
                raise typer.Exit(2) from None
            err.print("verdict: failed", markup=False, soft_wrap=True)
            for line in (f"error: {exc}", *getattr(exc, "__notes__", ())):
                err.print(line, markup=False, soft_wrap=True)
            raise typer.Exit(1) from None
        except DualarmError as exc:
            err.print(excerpt(f"error: {exc}", MAX_LINE), markup=False, soft_wrap=True)
            raise typer.Exit(2) from None
        except (KeyboardInterrupt, Terminated) as exc:
            if not received:  # raised without our handler (outside the main thread)
                received.append(signal.SIGINT if isinstance(exc, KeyboardInterrupt) else signal.SIGTERM)
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
            sys.unraisablehook = sys.__unraisablehook__
            if received:  # also when a library swallowed the exception (CasADi turns it into a failed solve)
                what = "interrupted (SIGINT)" if received[0] == signal.SIGINT else "terminated (SIGTERM)"
                err.print(what, markup=False)
                raise typer.Exit(
                    EXIT_CODES[what]
                ) from None  # the signal decides the exit code, whatever the command was doing

    return wrapper


#: The signals the running command received.
_received: list[int] = []


def _raise_swallowed() -> None:
    """Raise again a signal the command received whose exception a library swallowed.

    CasADi turns it into a failed solve. Called between stages.
    """
    if _received:
        raise KeyboardInterrupt if _received[0] == signal.SIGINT else Terminated()


def _unraisable(unraisable: Any) -> None:
    """``sys.unraisablehook``: silent for the exception of a signal; Python's own hook for anything else.

    Python cannot raise the exception of a signal from a ``__del__`` (:func:`_raise_swallowed`
    raises it again).
    """
    if not issubclass(unraisable.exc_type, (KeyboardInterrupt, Terminated)):
        sys.__unraisablehook__(unraisable)


def _update(status: Status, text: str) -> None:
    """Show ``text`` on the status line, once :func:`_raise_swallowed` let the command go on."""
    _raise_swallowed()
    status.update(text)


def _catch_signals(received: list[int]) -> dict[int, Any]:
    """Install the command's SIGINT and SIGTERM handlers; returns the handlers they replace.

    Each appends its signal to ``received`` and raises (KeyboardInterrupt or
    :class:`~dualarm.errors.Terminated`), so that a run being recorded is kept as failed. SIGINT
    is left alone when it is ignored (a command started in the background); outside the main
    thread nothing is installed.
    """
    if threading.current_thread() is not threading.main_thread():
        return {}

    def handler(signum: int, frame: object) -> None:
        received.append(signum)
        raise KeyboardInterrupt if signum == signal.SIGINT else Terminated()

    sys.unraisablehook = _unraisable  # a signal raised in a __del__ is raised again between stages, without a traceback

    previous: dict[int, Any] = {signal.SIGTERM: signal.signal(signal.SIGTERM, handler)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, handler)
    return previous
