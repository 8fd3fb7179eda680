"""The Dask cluster that studies and reproductions run on.

:func:`connect` gives a client of an existing cluster, named by its scheduler's address (as
dask-jobqueue and dask-kubernetes clusters are used), or of a new ``LocalCluster`` of worker
processes, one thread each. Either way each worker is set up once (:class:`WorkerSetup`): glibc's
allocator given back the thresholds Dask's nanny takes away, and, in a ``LocalCluster``, SIGINT
ignored (Ctrl-C reaches the whole process group; it is the client's to handle) and each worker
pinned to a core of its own. A task that must be stopped when the client is interrupted runs
inside :func:`dualarm.interrupt.stoppable` under its key; :func:`stop_tasks` stops it on whichever
worker runs it.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import sys
import threading
from collections.abc import Collection, Iterator
from typing import TYPE_CHECKING, Any

from distributed import WorkerPlugin

from dualarm.errors import DualarmError, Terminated, excerpt
from dualarm.interrupt import stop

if TYPE_CHECKING:
    from distributed import Client, Future, Worker

__all__ = [
    "ALLOWED_FAILURES",
    "LOCAL",
    "WORKER_ENVIRON",
    "WorkerSetup",
    "connect",
    "local_cores",
    "pin_to_core",
    "stop_tasks",
    "worker_name",
]

#: How long a client tries to reach a scheduler named by its address [s] (Dask retries a refused connection until then).
CONNECT_TIMEOUT_S = 30.0
#: Times a task may take a worker down with it before it fails (Dask's ``distributed.scheduler.allowed-failures``).
ALLOWED_FAILURES = 3
#: The environment a ``LocalCluster``'s worker starts with: what Dask's nanny sets, but for
#: ``MALLOC_TRIM_THRESHOLD_`` (:class:`WorkerSetup` undoes that one in other clusters' workers).
WORKER_ENVIRON = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
#: The address every server of a ``LocalCluster`` listens on: this machine only.
LOCAL_HOST = "127.0.0.1"
#: Dask settings of the ``LocalCluster``: a task that took down :data:`ALLOWED_FAILURES` workers
#: fails; no statistical profiler in the workers (it samples every thread's stack every 10 ms: 5 %
#: of a study's trial here); the workers' environment :data:`WORKER_ENVIRON`.
LOCAL_CLUSTER_CONFIG = {
    "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
    "distributed.worker.profile.enabled": False,
    "distributed.nanny.pre-spawn-environ": WORKER_ENVIRON,
}
#: The worker name of work run outside Dask.
LOCAL = "local"
#: glibc's ``mallopt`` parameters (malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: How long a stopped task may take to close its run [s].
STOP_WAIT_S = 120.0


def _undo_malloc_trim() -> None:
    """Give glibc's allocator back the thresholds Dask's nanny took away.

    A nanny starts its worker with ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes glibc's mmap
    threshold at 128 kB: every array above it (MC-Inverse's arm-angle search allocates MBs per
    sample) is mapped and unmapped again. Measured on this machine: MC-Inverse 4.6x slower and a
    study trial's sys time 40 % of its wall time. Sets the mmap threshold to 32 MiB and the trim
    threshold to 64 MiB (glibc's dynamic ceilings) with ``mallopt``; nothing elsewhere.
    """
    if "MALLOC_TRIM_THRESHOLD_" not in os.environ or not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_MMAP_THRESHOLD, 32 * 2**20)
        libc.mallopt(M_TRIM_THRESHOLD, 64 * 2**20)
    except (OSError, AttributeError):  # not glibc
        pass


def _unraisable(unraisable: Any) -> None:
    """A worker's ``sys.unraisablehook``: silent for a stop's :class:`Terminated` raised in a ``__del__``.

    The task raises it again between stages. Python's own hook otherwise.
    """
    if not issubclass(unraisable.exc_type, Terminated):
        sys.__unraisablehook__(unraisable)


def pin_to_core(core: int) -> None:
    """Keep this process on CPU ``core``: every thread it has, and those they start, which inherit it.

    Linux's affinity is per thread. Nothing where the OS cannot.
    """
    if not hasattr(os, "sched_setaffinity"):
        return
    threads = [int(t) for t in os.listdir("/proc/self/task")] if os.path.isdir("/proc/self/task") else [0]
    for thread in threads:
        with contextlib.suppress(OSError):  # a thread that has ended meanwhile
            os.sched_setaffinity(thread, {core})


def local_cores(workers: int) -> tuple[int, ...]:
    """The cores a ``LocalCluster`` of ``workers`` pins its workers to, worker i to the i-th.

    This process's, when there are at least as many (else none: the OS places them).
    """
    cores = tuple(sorted(os.sched_getaffinity(0))) if hasattr(os, "sched_getaffinity") else ()
    return cores if workers <= len(cores) else ()


def _without_gc_diagnosis() -> None:
    """Remove the garbage-collection callback a Dask scheduler or worker installs in its process.

    It logs GC times at INFO level only.

    A stop's or a signal's exception raised inside it (the callback runs wherever a collection
    starts) leaves its timer broken, and its next call prints "Exception ignored in: ...
    GCDiagnosis._gc_callback" with a traceback (seen in the interrupted-reproduction test).
    """
    from distributed.gc import disable_gc_diagnosis

    disable_gc_diagnosis(force=True)


class WorkerSetup(WorkerPlugin):
    """What each worker does once, as it starts (a Dask ``WorkerPlugin``).

    Its ``setup`` runs in the worker's main thread.

    Args:
        local: a ``LocalCluster``'s worker, a child of the client's process: it ignores SIGINT.
        cores: the cores of a ``LocalCluster``'s workers (:func:`local_cores`): worker i (its name)
            is pinned to the i-th, so that a worker's threads (TRAC-IK runs two per solve) do not
            take another worker's core. Measured on this 2-core machine, 40 trials on 2 workers:
            0.632 and 0.664 trials/s per worker pinned, 0.582 and 0.570 not (TRAC-IK 0.16 s per
            trial against 0.27-0.33 s).
    """

    name = "dualarm-setup"

    def __init__(self, local: bool, cores: tuple[int, ...] = ()) -> None:
        self.local, self.cores = local, cores

    def setup(self, worker: Worker) -> None:
        """Set ``worker``'s process up (class docstring)."""
        _undo_malloc_trim()
        sys.unraisablehook = _unraisable
        _without_gc_diagnosis()
        if self.local and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        if self.cores and isinstance(worker.name, int):
            pin_to_core(self.cores[worker.name % len(self.cores)])


def worker_name() -> str:
    """The Dask worker running this task (its name), or :data:`LOCAL` outside one."""
    try:
        from distributed import get_worker

        return str(get_worker().name)
    except (ImportError, ValueError):
        return LOCAL


def _is_a_scheduler(scheduler: str) -> None:
    """Refuse ``scheduler`` unless a Dask scheduler answers there in time (:data:`CONNECT_TIMEOUT_S`).

    Handshake included: its ``identity``, asked over Dask's own comm, in a thread with an event loop of its own (so
    also where one runs, as in a notebook). Dask's ``Client`` bounds the connection but not the handshake (a server
    that accepts and never answers held it forever), and reads another protocol's bytes as a frame's length (an HTTP
    server's reply made it allocate 3 EiB).

    Raises:
        DualarmError: nothing answers in time, or something that is not a Dask scheduler (one line).
    """
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from distributed.comm import connect as open_comm

    async def identity() -> Any:
        comm = await open_comm(scheduler, timeout=CONNECT_TIMEOUT_S)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def ask() -> Any:
        return asyncio.run(asyncio.wait_for(identity(), CONNECT_TIMEOUT_S))

    with ThreadPoolExecutor(1) as pool:
        try:
            reply = pool.submit(ask).result()
        except TimeoutError:
            raise DualarmError(
                f"--scheduler {excerpt(scheduler)}: no Dask scheduler answers there within {CONNECT_TIMEOUT_S:g} s"
            ) from None
        except OSError as exc:
            raise DualarmError(
                f"--scheduler {excerpt(scheduler)}: no Dask scheduler answers there "
                f"({type(exc).__name__}: {excerpt(str(exc), 120)})"
            ) from None
        except (Exception, MemoryError) as exc:  # whatever another protocol's bytes make of Dask's reader
            raise DualarmError(
                f"--scheduler {excerpt(scheduler)}: something answers there, but not in Dask's protocol "
                f"({type(exc).__name__})"
            ) from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise DualarmError(f"--scheduler {excerpt(scheduler)}: something answers there, but not a Dask scheduler")


@contextlib.contextmanager
def connect(scheduler: str | None = None, workers: int | None = None) -> Iterator[Client]:
    """A Dask client of the cluster at ``scheduler``, else of a new ``LocalCluster``; closed at the end.

    ``scheduler`` is ``tcp://HOST:PORT``; the ``LocalCluster`` has ``workers`` processes (default
    one per core), one thread each.

    Raises:
        DualarmError: ``scheduler`` cannot be reached, or is no Dask scheduler (within :data:`CONNECT_TIMEOUT_S`,
            handshake included), or ``workers`` < 1.
    """
    import dask
    from distributed import Client, LocalCluster
    from distributed.deploy.spec import SpecCluster

    if scheduler is not None:  # its own allowed-failures holds (Dask's default is 3 too)
        _is_a_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise DualarmError(
                f"--scheduler {excerpt(scheduler)}: no Dask scheduler answers "
                f"there ({type(exc).__name__}: {excerpt(str(exc), 120)})"
            ) from None
        with client:
            client.register_plugin(WorkerSetup(local=False))
            yield client
        return
    n = workers if workers is not None else os.cpu_count() or 1
    if n < 1:
        raise DualarmError(f"--workers {n}: give at least 1 worker")
    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        # Every server on LOCAL_HOST (the scheduler, its HTTP routes, the workers and their nannies): none is
        # authenticated, so none is reachable from another machine. The HTTP routes on a free port (on 8787, a warning
        # when it is taken); bokeh's dashboard is not installed.
        # Dask's own logs silenced up to ERROR: a task's failure comes back as its exception (a failed row or part), and
        # an interrupted command's workers, stopped as the scheduler closes, logged "Failed to communicate with
        # scheduler during heartbeat" with a traceback (seen once in CI, under SIGTERM).
        with contextlib.ExitStack() as stack:
            started = set(SpecCluster._instances)
            try:
                cluster = stack.enter_context(
                    LocalCluster(
                        n_workers=n,
                        threads_per_worker=1,
                        processes=True,
                        host=LOCAL_HOST,
                        dashboard_address=f"{LOCAL_HOST}:0",
                        silence_logs=logging.CRITICAL,
                    )
                )
            except BaseException as exc:
                # Dask's exit hook would close the half-started cluster and fail on its workers' state with a
                # traceback (Ctrl-C while it starts); its worker processes end with this one.
                SpecCluster._instances.difference_update(set(SpecCluster._instances) - started)
                if isinstance(exc, RuntimeError):  # "Nanny failed to start": a worker process was killed while starting
                    raise DualarmError(
                        f"the local Dask cluster did not start ({excerpt(str(exc), 120)}); nothing ran, run it again"
                    ) from None
                raise
            client = stack.enter_context(Client(cluster))
            _without_gc_diagnosis()  # this process's, which the LocalCluster's scheduler installed
            client.register_plugin(WorkerSetup(local=True, cores=local_cores(n)))
            yield client


def stop_tasks(client: Client, futures: Collection[Future]) -> None:
    """Stop the tasks of ``futures`` on every worker, and wait up to :data:`STOP_WAIT_S` for them to end.

    Each runs inside :func:`~dualarm.interrupt.stoppable` under its key.
    """
    from distributed import wait

    with contextlib.suppress(Exception):  # a worker that cannot be reached has nothing to close
        client.run(stop, [str(f.key) for f in futures])
        wait(list(futures), timeout=STOP_WAIT_S)
