"""The products passed between stages (numpy only).

The bottom layer, which imports nothing of dualarm but errors and arrays.

Task -> :class:`CartesianReference` (path) -> :class:`JointPath` (ik or plan) -> :class:`JointTrajectory`
(retime, smooth, approach) -> :class:`ExecutionLog` (execute); a run's products, metrics and
:class:`Verdict` are its :class:`RunResult`.
"""

from dualarm.contracts.execution import ContactEvent, ExecutionLog, PairContact
from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference, HandReference
from dualarm.contracts.run import ALL_STAGES, RunResult
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import Checks, Verdict, Violation

__all__ = [
    "ALL_STAGES",
    "CartesianReference",
    "Checks",
    "ContactEvent",
    "ExecutionLog",
    "HandReference",
    "JointPath",
    "JointTrajectory",
    "PairContact",
    "RunResult",
    "Verdict",
    "Violation",
]
