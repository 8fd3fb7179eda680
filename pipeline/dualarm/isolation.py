"""A call run in a process of its own: a crash in a C extension cannot take the command down silently.

Ruckig's C++ (signal 11 in ``calculate``, ruckig 0.19.4) and PyBullet's URDF loader (signal 11 on a malformed tree)
have ended whole commands without a message. :func:`isolated` runs the call in a spawned process: its result comes
back, a :class:`~dualarm.errors.DualarmError` it raises is raised again here (same class, same message), and a crash
is a :class:`CrashedError` naming the exit code or signal.
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable
from typing import Any

from dualarm.errors import DualarmError


class CrashedError(Exception):
    """The process that ran a call ended without a result (a crash in a C extension).

    Attributes:
        why: how it ended: ``signal 11 (SIGSEGV)``, or ``exit`` and its code.
    """

    def __init__(self, function: str, why: str) -> None:
        super().__init__(f"the process running {function} ended without a result: {why}")
        self.why = why


def isolated(function: Callable[..., Any], *args: Any) -> Any:
    """``function(*args)`` run in a spawned process; its result, or its DualarmError raised here.

    ``function`` and ``args`` must pickle (a module-level function).

    Raises:
        CrashedError: the process ended without a result (named: the signal, or the exit code).
        DualarmError: the one ``function`` raised, of its class, with its message.
    """
    context = multiprocessing.get_context("spawn")
    receive, send = context.Pipe(duplex=False)
    process = context.Process(target=_send_result, args=(send, function, args))
    process.start()
    send.close()
    try:
        kind, value = receive.recv()
    except EOFError:
        process.join()
        code = process.exitcode
        why = f"signal {-code} ({signal.Signals(-code).name})" if code is not None and code < 0 else f"exit {code}"
        raise CrashedError(function.__name__, why) from None
    process.join()
    if kind == "error":
        error_class, message = value
        raise error_class(message)
    return value


def _send_result(send: Any, function: Callable[..., Any], args: tuple[Any, ...]) -> None:
    """Run ``function(*args)`` and send ("ok", result) or ("error", (the DualarmError's class, message))."""
    try:
        send.send(("ok", function(*args)))
    except DualarmError as error:
        send.send(("error", (type(error), str(error))))
    finally:
        send.close()
