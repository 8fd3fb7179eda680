"""The one exception hierarchy of dualarm.

Every error a user can cause derives from :class:`DualarmError`; the CLI prints its message as one
line on stderr and exits with code 2, except a :class:`StageError` (a run that failed on valid
input, its verdict ``failed``): exit code 1. Messages name the file, key, argument or joint at fault;
errors that carry data (the sample, the time, the joint) carry it as attributes too, so code that
catches them need not parse the message.

- :class:`InvalidArgumentError` (also a ``ValueError``): a public function was called with an
  argument of the wrong shape or value; ``argument`` names it.
- :class:`RobotModelError`, :class:`NotSRSError`: a robot description is unusable.
- :class:`TaskFileError`, :class:`UnreachablePoseError`: a task is malformed or impossible.
- :class:`RecordingError`: a run directory or recording is missing, incomplete or corrupt.
- :class:`StageError`, :class:`NoSolutionFound`: a pipeline stage failed on valid input.
- :class:`OutputError`: an output path cannot be written without harm (not a directory dualarm
  made, holding a file it did not write, locked by another process, or refused by the system).

:class:`Terminated` is not a user's mistake: it is SIGTERM, turned into an exception as Ctrl-C is.
Messages quote a user's strings through :func:`excerpt`.
"""

from __future__ import annotations

from pathlib import Path


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
        violations: the checks that made the stage refuse its input (:class:`~dualarm.contracts.verdict.Violation`;
            the execute stage refusing a trajectory), recorded with the failed run.
        run_directory: where a recorded run that failed is kept (set by
            :func:`~dualarm.run.record_stages`), else None.
    """

    run_directory: Path | None = None

    def __init__(
        self,
        message: str,
        *,
        stage: str = "",
        sample: int | None = None,
        t_s: float | None = None,
        joint: str | None = None,
        violations: tuple = (),
    ) -> None:
        super().__init__(message)
        self.stage, self.sample, self.t_s, self.joint, self.violations = stage, sample, t_s, joint, tuple(violations)


class NoSolutionFound(StageError):
    """An IK solver found no valid solution for a pose (the reasons per candidate in the message)."""


class OutputError(DualarmError):
    """An output path cannot be written without harm.

    It is not a directory dualarm made, holds an entry dualarm did not write, is in use by another
    dualarm process, or the system refuses it (the message names the path and the cause).

    Attributes:
        path: the path at fault.
    """

    def __init__(self, message: str, path: str = "") -> None:
        super().__init__(message)
        self.path = path


class Terminated(SystemExit):
    """The process received SIGTERM.

    Raised by :meth:`on_sigterm`, the handler the command line and the reproduction's workers
    install, so that SIGTERM unwinds the stack as Ctrl-C's KeyboardInterrupt does: a run being
    recorded is kept as failed with its files closed. It is a SystemExit with code 143, as the usual
    ``sys.exit`` handler raises: ``except Exception`` does not catch it and a process it ends prints
    no traceback.
    """

    def __init__(self) -> None:
        super().__init__(143)

    def __str__(self) -> str:
        return "SIGTERM"

    @classmethod
    def on_sigterm(cls, signum: int, frame: object) -> None:
        """A ``signal.signal`` handler: raise :class:`Terminated`."""
        raise cls()


def excerpt(text: object, limit: int = 80) -> str:
    """``str(text)`` as a message may quote it: at most ``limit`` characters (its middle cut to "...").

    Control characters are escaped as in a Python literal, so that it stays one line and cannot
    drive a terminal.
    """
    s = str(text)
    if len(s) > limit:
        head = (limit - 3) // 2
        s = s[:head] + "..." + s[len(s) - (limit - 3 - head) :]
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in s)
