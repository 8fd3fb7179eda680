"""How running work is stopped so that a run being recorded is kept as failed, with its files closed.

In the main thread, SIGINT and SIGTERM raise KeyboardInterrupt or
:class:`~dualarm.errors.Terminated` (the command line's handlers). A Dask task runs in a worker's
thread, which no signal reaches: the process that submitted it stops it with :func:`stop`
(through ``Client.run``), which raises :class:`~dualarm.errors.Terminated` in the threads running
the work it names, as a signal's handler would in the main thread (at the thread's next Python
instruction). Work that can be stopped so runs inside :func:`stoppable`; a block that must not
be cut (building a Rerun stream) runs inside :func:`held`, which keeps a signal or a stop back
until it ends.
"""

from __future__ import annotations

import ctypes
import signal
import threading
from collections.abc import Collection, Iterator
from contextlib import contextmanager

from dualarm.errors import Terminated

__all__ = ["held", "stop", "stop_requested", "stoppable"]

_lock = threading.Lock()
#: Thread id -> the token of the stoppable work it runs.
_running: dict[int, str] = {}
#: The threads inside :func:`held`, and those of them a stop waits for.
_holding: set[int] = set()
_pending: set[int] = set()
#: The tokens :func:`stop` was given (work that starts afterwards under one is stopped at once).
_stopped: set[str] = set()


def _raise_in(thread_id: int, exception: type[BaseException] | None) -> None:
    """Raise ``exception`` in thread ``thread_id`` at its next Python instruction.

    None: take back one not yet raised.
    """
    ctypes.pythonapi.PyThreadState_SetAsyncExc(
        ctypes.c_ulong(thread_id), ctypes.py_object(exception) if exception else None
    )


@contextmanager
def stoppable(token: str) -> Iterator[None]:
    """Run the block so that :func:`stop` given ``token`` raises :class:`Terminated` in it.

    Raises it at once if ``token`` was stopped already.
    """
    thread = threading.get_ident()
    with _lock:
        if token in _stopped:
            raise Terminated()
        _running[thread] = token
    try:
        yield
    finally:
        with _lock:
            del _running[thread]
            _raise_in(thread, None)  # a stop that came as the block ended is not raised outside it


def stop(tokens: Collection[str]) -> int:
    """Stop the work running under ``tokens`` in this process (:func:`stoppable`).

    And any that starts under them later. Returns the threads stopped now.
    """
    with _lock:
        new = set(tokens) - _stopped
        _stopped.update(new)
        threads = [t for t, token in _running.items() if token in new]
        for thread in threads:
            if thread in _holding:
                _pending.add(thread)
            else:
                _raise_in(thread, Terminated)
    return len(threads)


def stop_requested() -> bool:
    """Whether the work this thread runs was stopped.

    Its :class:`Terminated` may have been swallowed by a library: CasADi turns it into a failed
    solve.
    """
    return _running.get(threading.get_ident()) in _stopped


@contextmanager
def held() -> Iterator[list[int]]:
    """SIGINT and SIGTERM, or a :func:`stop`, held back until the block ends, then raised.

    The signals in the main thread, a :func:`stop` in another.

    A signal's exception raised inside ``rr.RecordingStream()`` leaves a half-built stream whose
    ``__del__`` prints a traceback; one raised inside Dask's garbage-collection callback leaves it
    broken, and its next call prints one. Yields the signals held so far (a list the block may
    watch, to end early; always empty outside the main thread). A signal that is ignored stays
    ignored (SIGINT in a command started in the background): held, it would end a block that
    watches the list, and raising it afterwards would do nothing.
    """
    if threading.current_thread() is threading.main_thread():
        signals: list[int] = []
        caught = [
            signum for signum in (signal.SIGINT, signal.SIGTERM) if signal.getsignal(signum) is not signal.SIG_IGN
        ]
        previous = {signum: signal.signal(signum, lambda signum, frame: signals.append(signum)) for signum in caught}
        try:
            yield signals
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
            for held_signal in dict.fromkeys(signals):
                signal.raise_signal(held_signal)
        return
    thread = threading.get_ident()
    with _lock:
        _holding.add(thread)
    try:
        yield []
    finally:
        with _lock:
            _holding.discard(thread)
            stopped = thread in _pending
            _pending.discard(thread)
        if stopped:
            raise Terminated()
