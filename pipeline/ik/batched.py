"""Evaluating a per-pose candidates Function over many poses in mapped CasADi calls.

Analytic IK solvers (MC-Inverse, ikfast-style) are CasADi Functions
``(T (4x4) hand pose [m], x (scalar)) -> (Q (7xC) [rad], reason (1xC))`` with a scalar x (the arm
angle, a free joint value). Building ``Function.map(N)`` costs time in N, and a plain call spends
most of its time converting the outputs to numpy; so one map of a fixed chunk size is built per
Function and called through a CasADi ``FunctionBuffer`` on flat column-major arrays, with its
instances spread over the machine's cores.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property

import casadi as cs
import numpy as np

#: Threads that share a mapped call (one per core).
THREADS = os.cpu_count() or 1


@dataclass(frozen=True)
class BatchedCandidates:
    """``function`` mapped over ``chunk`` poses at a time.

    Attributes:
        function: ``(T (4x4), x) -> (Q (7xC), reason (1xC))``.
        chunk: poses per mapped call.
    """

    function: cs.Function
    chunk: int = 4096

    @cached_property
    def _buffer(self):
        mapped = self.function.map(self.chunk, "thread", THREADS)
        buffer, evaluate = mapped.buffer()
        arrays = (np.zeros(mapped.numel_in(0)), np.zeros(mapped.numel_in(1)), np.zeros(mapped.numel_out(0)), np.zeros(mapped.numel_out(1)))
        buffer.set_arg(0, memoryview(arrays[0]))
        buffer.set_arg(1, memoryview(arrays[1]))
        buffer.set_res(0, memoryview(arrays[2]))
        buffer.set_res(1, memoryview(arrays[3]))

        def run(_keep=buffer) -> None:
            evaluate()

        return run, arrays

    def __call__(self, poses: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates of N poses (N, 4, 4) [m] at scalars x (N,) (or one for all).

        Returns:
            Q (N, C, n) [rad] and reason codes (N, C).
        """
        poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
        x = np.broadcast_to(np.asarray(x, dtype=float), poses.shape[:1])
        n, C = self.function.size1_out(0), self.function.size2_out(0)
        N, chunk = poses.shape[0], self.chunk
        q, reason = np.empty((N, C, n)), np.empty((N, C), int)
        evaluate, (T, values, Q, code) = self._buffer
        for start in range(0, N, chunk):
            m = min(chunk, N - start)
            T.reshape(chunk, 4, 4)[:m] = poses[start : start + m].transpose(0, 2, 1)  # column-major
            values[:m] = x[start : start + m]
            evaluate()
            q[start : start + m] = Q.reshape(chunk, C, n)[:m]
            reason[start : start + m] = code.reshape(chunk, C)[:m]
        return q, reason
