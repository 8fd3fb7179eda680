"""``Task``: a validated task file with its robot, and the hands' poses at joint configurations."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualarm.errors import excerpt
from dualarm.model.kinematics import ChainKinematics, hand_pose
from dualarm.model.poses import pose_matrix
from dualarm.model.robot import Chain, Robot
from dualarm.tasks.schema import TaskSpec


@dataclass(frozen=True)
class Task:
    """A validated task.

    Attributes:
        spec: the parsed file (or dict).
        file: where it was read from; None for a task made from a dict.
        text: the source's exact text (TOML for a file, JSON for a dict; recorded as an attachment).
        robot: the robot it names, with the task's ``[limits]`` applied.
        initial_q: the initial configuration, every movable joint of the robot [rad].
    """

    spec: TaskSpec
    file: Path | None
    text: str
    robot: Robot
    initial_q: Mapping[str, float]

    @property
    def name(self) -> str:
        """The task's name (also its recordings directory)."""
        return self.spec.name

    @property
    def sha256(self) -> str:
        """SHA-256 of the source's text."""
        return hashlib.sha256(self.text.encode()).hexdigest()

    @property
    def source_name(self) -> str:
        """The file name of the task's source (``<name>.json`` for a task made from a dict)."""
        return self.file.name if self.file is not None else f"{self.name}.json"

    def where(self, key: str) -> str:
        """``file:key`` for error messages (``<dict>:key`` for a task made from a dict)."""
        return f"{excerpt(self.file) if self.file is not None else '<dict>'}:{key}"

    def hand_chain_from_root(self, hand: str) -> Chain:
        """The chain from the robot's root link to ``hand``'s tip (waist included)."""
        return self.robot.chain_between(self.robot.urdf.root, self.robot.hand_chain(hand).tip)

    def initial_hand_pose(self, hand: str) -> np.ndarray:
        """The pose of ``hand`` at the initial configuration, in the robot base frame (4x4) [m]."""
        return hand_pose(self.robot, hand, self.initial_q)

    def hand_poses(
        self, joint_names: tuple[str, ...], q: np.ndarray, fixed: Mapping[str, float]
    ) -> dict[str, np.ndarray]:
        """Each driven hand's pose (N, 4, 4) [m] at configurations ``q`` (N, n) [rad] of ``joint_names``.

        The other joints at ``fixed`` or else at their initial values.
        """
        return hand_poses_at(self.robot, self.spec.hands, joint_names, q, {**self.initial_q, **fixed})

    def waypoint_pose(self, name: str) -> np.ndarray:
        """The 4x4 pose of waypoint ``name`` [m]."""
        wp = self.spec.waypoints[name]
        return pose_matrix(wp.position, wp.rpy)

    def start_pose(self, hand: str) -> np.ndarray:
        """The start pose of a driven hand (``initial`` or a waypoint) [m]."""
        start = getattr(self.spec.start, hand)
        return self.initial_hand_pose(hand) if start == "initial" else self.waypoint_pose(start)


def hand_poses_at(
    robot: Robot, hands: Sequence[str], joint_names: Sequence[str], q: np.ndarray, others: Mapping[str, float]
) -> dict[str, np.ndarray]:
    """Each of ``hands``' pose (N, 4, 4) [m] in the robot base frame at configurations ``q`` (N, n) [rad].

    ``q`` of ``joint_names``, every other joint at its value in ``others`` [rad].
    """
    q = np.asarray(q, dtype=float).reshape(-1, len(joint_names))
    columns = {n: q[:, i] for i, n in enumerate(joint_names)}
    poses = {}
    for hand in hands:
        chain = robot.chain_between(robot.urdf.root, robot.hand_chain(hand).tip)
        Q = np.stack([columns[n] if n in columns else np.full(len(q), others[n]) for n in chain.joint_names], axis=1)
        poses[hand] = ChainKinematics.of(chain).poses(Q)
    return poses
