"""Evaluating a per-pose candidates Function over many poses in mapped CasADi calls.

Analytic IK solvers (MC-Inverse, ikfast-style) are CasADi Functions
``(T (4x4) hand pose [m], x (scalar)) -> (Q (7xC) [rad], reason (1xC))`` with a scalar x (the arm
angle, a free joint value). Building ``Function.map(N)`` costs time in N, and a plain call spends
most of its time converting the outputs to numpy; so one map of a fixed chunk size is built per
Function (and a smaller one for a last, partial chunk) and called through a CasADi ``FunctionBuffer`` on flat column-major arrays, with its
instances spread over the machine's cores.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import casadi as cs
import numpy as np

#: Threads that share a mapped call (one per core).
THREADS = os.cpu_count() or 1
#: The last, partial chunk is mapped over its size rounded up to a multiple of this (few maps to build).
REST_STEP = 64


@dataclass(frozen=True)
class BatchedCandidates:
    """``function`` mapped over ``chunk`` poses at a time.

    Attributes:
        function: ``(T (4x4), x) -> (Q (7xC), reason (1xC))``.
        chunk: poses per mapped call.
    """

    function: cs.Function
    chunk: int = 4096

    _buffers: dict = field(default_factory=dict, repr=False, compare=False)

    def _buffer(self, size: int):
        """The Function mapped over ``size`` poses with its FunctionBuffer (built once per size)."""
        if size not in self._buffers:
            mapped = self.function.map(size, "thread", THREADS)
            buffer, evaluate = mapped.buffer()
            arrays = (np.zeros(mapped.numel_in(0)), np.zeros(mapped.numel_in(1)), np.zeros(mapped.numel_out(0)), np.zeros(mapped.numel_out(1)))
            buffer.set_arg(0, arrays[0].data)
            buffer.set_arg(1, arrays[1].data)
            buffer.set_res(0, arrays[2].data)
            buffer.set_res(1, arrays[3].data)

            def run(_keep=buffer) -> None:
                evaluate()

            self._buffers[size] = (run, arrays)
        return self._buffers[size]

    def __call__(self, poses: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates of N poses (N, 4, 4) [m] at scalars x (N,) (or one for all): full chunks, then the rest in a map of the rest's size rounded up to :data:`REST_STEP`.

        Returns:
            Q (N, C, n) [rad] and reason codes (N, C).
        """
        poses = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
        x = np.broadcast_to(np.asarray(x, dtype=float), poses.shape[:1])
        n, C = self.function.size1_out(0), self.function.size2_out(0)
        N = poses.shape[0]
        q, reason = np.empty((N, C, n)), np.empty((N, C), int)
        for start in range(0, N, self.chunk):
            m = min(self.chunk, N - start)
            size = self.chunk if m == self.chunk else min(self.chunk, -(-m // REST_STEP) * REST_STEP)
            evaluate, (T, values, Q, code) = self._buffer(size)
            T.reshape(size, 4, 4)[:m] = poses[start : start + m].transpose(0, 2, 1)  # column-major
            values[:m] = x[start : start + m]
            evaluate()
            q[start : start + m] = Q.reshape(size, C, n)[:m]
            reason[start : start + m] = code.reshape(size, C)[:m]
        return q, reason
