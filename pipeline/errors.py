"""The one exception hierarchy of dualarm.

Every error a user can cause derives from :class:`DualarmError`; the CLI prints its message as one
line on stderr and exits with code 2. Messages name the file, key, argument or joint at fault;
errors that carry data (the sample, the time, the joint) carry it as attributes too, so code that
catches them need not parse the message.

- :class:`InvalidArgumentError` (also a ``ValueError``): a public function was called with an
  argument of the wrong shape or value; ``argument`` names it.
- :class:`RobotModelError`, :class:`NotSRSError`: a robot description is unusable.
- :class:`TaskFileError`, :class:`UnreachablePoseError`: a task is malformed or impossible.
- :class:`RecordingError`: a run directory or recording is missing, incomplete or corrupt.
- :class:`StageError`, :class:`NoSolutionFound`: a pipeline stage failed on valid input.
"""

from __future__ import annotations


class DualarmError(Exception):
    """Base class of every error dualarm raises on purpose."""


class InvalidArgumentError(DualarmError, ValueError):
    """An argument of a public function has the wrong shape, type or value.

    Attributes:
        argument: the argument's name.
        joint: the joint at fault, or None.
    """

    def __init__(self, argument: str, message: str, *, joint: str | None = None) -> None:
        super().__init__(f"{argument}: {message}")
        self.argument, self.joint = argument, joint


class RobotModelError(DualarmError):
    """A robot directory, robot.toml or URDF is missing, malformed or inconsistent."""


class NotSRSError(RobotModelError):
    """A chain was required to be Spherical-Revolute-Spherical and is not.

    Attributes:
        chain: the chain's name.
    """

    def __init__(self, message: str, chain: str = "") -> None:
        super().__init__(message)
        self.chain = chain


class TaskFileError(DualarmError):
    """A task file is missing, malformed, or asks for something the robot cannot do."""


class UnreachablePoseError(TaskFileError):
    """A hand pose of a task lies outside the arm's workspace.

    Attributes:
        hand: the hand (``left``/``right``), or "" when not known.
    """

    def __init__(self, message: str, hand: str = "") -> None:
        super().__init__(message)
        self.hand = hand


class RecordingError(DualarmError):
    """A run directory or recording is missing, incomplete or corrupt."""


class StageError(DualarmError):
    """A pipeline stage failed on valid input (the run is recorded as failed).

    Attributes:
        stage: the stage (``ik``, ``retime``, ...), or "" when not known.
        sample: the index of the sample (or control step) where it failed, or None.
        t_s: the time of that sample [s], or None.
        joint: the joint at fault, or None.
    """

    def __init__(self, message: str, *, stage: str = "", sample: int | None = None, t_s: float | None = None, joint: str | None = None) -> None:
        super().__init__(message)
        self.stage, self.sample, self.t_s, self.joint = stage, sample, t_s, joint


class NoSolutionFound(StageError):
    """An IK solver found no valid solution for a pose (the reasons per candidate in the message)."""
