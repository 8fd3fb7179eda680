"""Contacts at a configuration, the values of joints in no chain, and the ``ready`` home pose."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import product

import numpy as np

from dualarm.describe.layout import lock_value
from dualarm.describe.tips import _zero_position
from dualarm.errors import RobotModelError
from dualarm.model.robot import Chain, Robot

#: Configurations sampled (fixed seed) to find pairs in contact everywhere and the ``ready`` pose.
SAMPLES = 400
#: Seed of every sample.
SEED = 0
#: ``ready`` keeps this fraction of each joint's range from either limit.
READY_LIMIT_MARGIN = 0.05
#: ``ready`` puts each hand at least this fraction of its arm's length in front of the arm's first joint (+x
#: of the root link).
READY_FORWARD = 0.25
#: ``ready`` keeps each hand at least this high above the root link's origin (a fixed base on the floor) [m].
READY_MIN_HEIGHT_M = 0.1
#: ``ready`` keeps each hand's distance from its arm's first joint within these fractions of the arm's
#: length: elbow bent, room to move every way.
READY_REACH = (0.4, 0.8)
#: ``ready`` keeps each hand at most this fraction of its arm's length further out sideways (away from the
#: root's x-z plane) than its arm's first joint.
READY_OUTWARD = 0.25
#: ``ready`` prefers the hand nearest this point, in arm lengths from the arm's first joint (forward,
#: sideways, up): in front and a little below, as a person holds a tool.
READY_TARGET = (0.55, 0.0, -0.25)


def _collision_world(robot: Robot):
    """PyBullet with self-collision and dualarm's touching pairs off; (sim, the skipped pairs)."""
    from dualarm.sim.world import disable_unchecked_pairs, load_pybullet_robot

    sim = load_pybullet_robot(robot.urdf.path, self_collision=True)
    return sim, disable_unchecked_pairs(sim, robot.disabled_pairs)


def contact_pairs(sim, q: Mapping[str, float]) -> set[tuple[str, str]]:
    """Link pairs of ``sim``'s robot (sorted names) that penetrate at ``q`` [rad].

    The pairs PyBullet checks.
    """
    from dualarm.sim.world import pb

    sim.set_positions(list(q), list(q.values()))
    pb.performCollisionDetection(physicsClientId=sim.client)
    name = sim.link_name
    pairs = set()
    for point in pb.getContactPoints(bodyA=sim.body, bodyB=sim.body, physicsClientId=sim.client):
        if point[8] < 0:
            a, b = sorted((name[point[3]], name[point[4]]))
            pairs.add((a, b))
    return pairs


def _samples(robot: Robot, joints: Sequence[str], n: int, seed: int, margin: float = 0.0) -> np.ndarray:
    lower, upper = robot.lower_upper(tuple(joints))
    lower, upper = np.where(np.isfinite(lower), lower, -np.pi), np.where(np.isfinite(upper), upper, np.pi)
    span = upper - lower
    return np.random.default_rng(seed).uniform(lower + margin * span, upper - margin * span, size=(n, len(joints)))


def held_values(robot: Robot, sim, chain_joints: Sequence[str]) -> dict[str, float]:
    """The value every movable joint in no chain is held at [rad].

    :func:`lock_value`, or else (when the links below it touch another link at the zero pose, as a Panda's closed
    fingers do) its upper limit, lower limit or middle, the first at which they do not.
    """
    urdf = robot.urdf
    held = {j.name: lock_value(j) for j in urdf.joints if j.movable and j.name not in chain_joints}
    for joint in list(held):
        below = urdf.subtree(urdf.joint(joint).child)
        j = urdf.joint(joint)
        options = [held[joint]] + [v for v in (j.upper, j.lower, (j.lower + j.upper) / 2) if np.isfinite(v)]
        for value in options:
            if not any(
                a in below or b in below
                for a, b in contact_pairs(sim, {**dict.fromkeys(chain_joints, 0.0), **held, joint: value})
            ):
                held[joint] = float(value)
                break
    return held


def arm_length(arm: Chain) -> float:
    """An arm's length [m]: the offsets of its joints from its first movable joint's to its tip, added up.

    Its reach when stretched out straight, whatever its zero pose (a Kinova Jaco's is folded).
    """
    joints = list(arm.joints)
    first = [j.movable for j in joints].index(True)
    return float(sum(np.linalg.norm(j.origin_xyz) for j in joints[first + 1 :]))


def ready_pose(
    robot: Robot, sim, base: Mapping[str, float], samples: int = SAMPLES * 10, seed: int = SEED
) -> dict[str, float]:
    """A ``ready`` home pose [rad] by joint.

    For each arm, random configurations within the limits (:data:`READY_LIMIT_MARGIN` in from each) whose hand is
    :data:`READY_FORWARD` of the arm's length in front of its first joint, :data:`READY_MIN_HEIGHT_M` above the
    root, at :data:`READY_REACH` of the arm's length from its first joint and at most :data:`READY_OUTWARD` of it
    further out sideways, the hand nearest :data:`READY_TARGET` first; the first combination of the arms clear of
    self-collision in PyBullet. The joints of no arm (a waist) at :func:`lock_value`, or where none is found there,
    at the middle, the top or the bottom of their ranges (a TIAGo's torso lift at 0 sinks the arms' first links
    into its column); the joints of ``base`` (in no chain) as given.

    Raises:
        RobotModelError: no such configuration among the samples at any of them (naming the arm).
    """
    arm_joints = {n for c in robot.chains.values() if c.hand for n in c.joint_names}
    waist = [j for j in robot.urdf.joints if j.movable and j.name not in arm_joints and j.name not in base]
    options = [lock_value] + [
        lambda j, f=f: float(j.lower + f * (j.upper - j.lower)) if np.isfinite(j.lower + j.upper) else lock_value(j)
        for f in (0.5, 1.0, 0.0)
    ]
    refusal = None
    for value in options:
        held = {**{j.name: value(j) for j in waist}, **base}
        try:
            return _ready_pose(robot, sim, held, samples, seed)
        except RobotModelError as exc:
            refusal = refusal or exc
            if not waist:
                break
    assert refusal is not None
    raise refusal


def _ready_pose(robot: Robot, sim, base: Mapping[str, float], samples: int, seed: int) -> dict[str, float]:
    """:func:`ready_pose` with every joint of no arm at ``base``."""
    from dualarm.model.kinematics import ChainKinematics

    base = {**{j.name: lock_value(j) for j in robot.urdf.joints if j.movable}, **base}
    arms = [c for c in robot.chains.values() if c.hand]
    moved_by = {arm.name: robot.urdf.subtree(next(j for j in arm.joints if j.movable).child) for arm in arms}
    candidates = []
    for k, arm in enumerate(arms):
        to_tip = robot.chain_between(robot.urdf.root, arm.tip)
        first = arm.joints[[j.movable for j in arm.joints].index(True)]
        shoulder = _zero_position(robot.urdf, first.child)
        length = arm_length(arm)
        moved = moved_by[arm.name]
        others = set().union(*(links for name, links in moved_by.items() if name != arm.name))
        Q = np.round(_samples(robot, arm.joint_names, samples, seed + k, READY_LIMIT_MARGIN), 3)
        full = np.array([[base.get(n, 0.0) for n in to_tip.joint_names]] * len(Q))
        columns = [to_tip.joint_names.index(n) for n in arm.joint_names]
        full[:, columns] = Q
        p = ChainKinematics.of(to_tip).poses(full)[:, :3, 3]
        reach = np.linalg.norm(p - shoulder, axis=1) / length
        outward = np.abs(p[:, 1]) - abs(shoulder[1])
        ok = (
            (p[:, 0] >= shoulder[0] + READY_FORWARD * length)
            & (p[:, 0] > 0)
            & (p[:, 2] >= READY_MIN_HEIGHT_M)
            & (reach >= READY_REACH[0])
            & (reach <= READY_REACH[1])
            & (outward <= READY_OUTWARD * length)
        )
        score = np.linalg.norm(
            p - (shoulder + length * np.array(READY_TARGET)), axis=1
        ) / length + 0.01 * np.linalg.norm(Q, axis=1)
        order = [i for i in np.argsort(score, kind="stable") if ok[i]]
        free = []
        for i in order:  # the other arm is checked with it below: here only the pairs this arm moves, not with it
            q = dict(zip(arm.joint_names, Q[i], strict=True))
            if not any(
                (a in moved or b in moved) and not (a in others or b in others)
                for a, b in contact_pairs(sim, {**base, **q})
            ):
                free.append(q)
            if len(free) == 8:
                break
        if not free:
            raise RobotModelError(
                f"robot init: no configuration of '{arm.name}' among {samples} samples has the hand in front "
                "and is clear of self-collision; write [home.ready] by hand"
            )
        candidates.append(free)
    for combination in sorted(product(*candidates), key=lambda qs: sum(np.linalg.norm(list(q.values())) for q in qs)):
        q = {k: v for part in combination for k, v in part.items()}
        if not contact_pairs(sim, {**base, **q}):
            return {**base, **q}
    raise RobotModelError(
        "robot init: the arms' candidate ready poses collide with each other; write [home.ready] by hand"
    )
