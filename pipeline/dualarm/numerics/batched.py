"""Evaluating a CasADi Function over many inputs in mapped calls, or on one input.

On one input without CasADi's Python call path.

A per-item Function (an analytic IK solver's ``(T (4x4) hand pose [m], x (scalar)) -> (Q (7xC)
[rad], reason (1xC))`` with x the arm angle or a free joint value, or a piece of the SEW search) is
evaluated over N items by :class:`Batched`. Building ``Function.map(N)`` costs time in N, and a
plain call spends most of its time converting the outputs to numpy; so one map of a fixed chunk size
is built per Function (and a smaller one for a last, partial chunk) and called through a CasADi
``FunctionBuffer`` on flat column-major arrays, with its instances spread over the machine's cores.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import casadi as cs
import numpy as np


def _threads() -> int:
    """One per core, or ``OMP_NUM_THREADS`` when it is set to a whole number.

    A Dask nanny sets it to 1 in its worker, as a study's workers are one core each: more threads
    per worker only make the workers wait for each other.
    """
    given = os.environ.get("OMP_NUM_THREADS", "")
    return int(given) if given.isdigit() and int(given) > 0 else os.cpu_count() or 1


#: Threads that share a mapped call (:func:`_threads`).
THREADS = _threads()
#: Maps over fewer items than this run serially (starting threads costs more than the items).
THREADED_FROM = 64


@dataclass(frozen=True)
class Batched:
    """``function`` mapped over ``chunk`` items at a time.

    Attributes:
        function: any CasADi Function of dense inputs (its outputs are made dense).
        chunk: items per mapped call.
    """

    function: cs.Function
    chunk: int = 4096

    _buffers: dict = field(default_factory=dict, repr=False, compare=False)

    def _buffer(self, size: int):
        """The Function mapped over ``size`` items with its FunctionBuffer and flat arrays.

        Built once per size.
        """
        if size not in self._buffers:
            f = self.function
            if not all(f.sparsity_out(i).is_dense() for i in range(f.n_out())):  # the buffers hold every entry
                args = f.mx_in()
                f = cs.Function(f.name(), args, [cs.densify(out) for out in f(*args)])
            mapped = f.map(size, "thread", THREADS) if size >= THREADED_FROM else f.map(size, "serial")
            buffer, evaluate = mapped.buffer()
            ins = [np.zeros(mapped.numel_in(i)) for i in range(mapped.n_in())]
            outs = [np.zeros(mapped.numel_out(i)) for i in range(mapped.n_out())]
            for i, array in enumerate(ins):
                buffer.set_arg(i, array.data)
            for i, array in enumerate(outs):
                buffer.set_res(i, array.data)

            def run(_keep=buffer) -> None:
                evaluate()

            self._buffers[size] = (run, ins, outs)
        return self._buffers[size]

    def __call__(self, *inputs: np.ndarray | float) -> tuple[np.ndarray, ...]:
        """Evaluate over N items: full chunks, then the rest in a map of its size rounded up to a power of two.

        Few maps to build, at most twice the work.

        Args:
            inputs: one per Function input of shape (r, c): N items (N, r, c), (N, r) for a column,
                (N,) for a scalar; or one value for all N.

        Returns:
            one array per output of shape (r, c): (N, r, c), or (N, r) for a column.
        """
        f = self.function
        flat = []
        for i, value in enumerate(inputs):
            r, c = f.size_in(i)
            flat.append(
                np.asarray(value, dtype=float).reshape(-1, r, c).transpose(0, 2, 1).reshape(-1, r * c)
            )  # column-major
        N = max(len(a) for a in flat)
        results = [np.empty((N, f.numel_out(i))) for i in range(f.n_out())]
        for start in range(0, N, self.chunk):
            m = min(self.chunk, N - start)
            size = min(self.chunk, 1 << (m - 1).bit_length())
            evaluate, ins, outs = self._buffer(size)
            for value, array in zip(flat, ins, strict=False):
                array.reshape(size, -1)[:m] = value if len(value) == 1 else value[start : start + m]
            evaluate()
            for result, array in zip(results, outs, strict=True):
                result[start : start + m] = array.reshape(size, -1)[:m]
        shaped = []
        for i, result in enumerate(results):
            r, c = f.size_out(i)
            shaped.append(result.reshape(N, r) if c == 1 else result.reshape(N, c, r).transpose(0, 2, 1))
        return tuple(shaped)


class BatchedCandidates(Batched):
    """An analytic IK solver's candidates Function mapped over many poses.

    The Function: ``(T (4x4), x) -> (Q (7xC), reason (1xC))``.
    """

    def candidates(self, poses: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates of N poses (N, 4, 4) [m] at scalars x (N,) (or one for all).

        Returns:
            Q (N, C, n) [rad] and reason codes (N, C).
        """
        poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
        Q, reason = self(poses, np.broadcast_to(np.asarray(x, dtype=float), poses.shape[:1]))
        return Q.transpose(0, 2, 1), reason[:, 0].astype(int)


class Single:
    """``function`` on one input through a ``FunctionBuffer``. Not thread-safe: one set of arrays.

    The inputs copied into preallocated arrays, every output written into one array, no conversion
    of CasADi types (a plain call costs ~30 µs more).
    """

    def __init__(self, function: cs.Function):
        self._buffer, self._evaluate = function.buffer()
        self._ins = [np.zeros(function.numel_in(i)) for i in range(function.n_in())]
        self._views = [
            a.reshape(function.size_in(i)[::-1]).T for i, a in enumerate(self._ins)
        ]  # (r, c) over column-major storage
        sizes = [function.numel_out(i) for i in range(function.n_out())]
        self._out = np.zeros(sum(sizes))
        for i, array in enumerate(self._ins):
            self._buffer.set_arg(i, array.data)
        for i, start in enumerate(np.cumsum([0, *sizes[:-1]])):
            self._buffer.set_res(i, self._out[start : start + sizes[i]].data)

    def __call__(self, *inputs: np.ndarray | float) -> np.ndarray:
        """Evaluate on one value per Function input (of its shape, or a number for a scalar).

        Returns the outputs one after the other, each flat in column-major order, in a new array.
        """
        for flat, view, value in zip(self._ins, self._views, inputs, strict=False):
            if flat.size == 1:
                flat[0] = value
            else:
                view[...] = value
        self._evaluate()
        return self._out.copy()
