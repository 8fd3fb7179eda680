"""Pose task space of TV-GDD and pinv (orientation rows under the position rows of eqs 24 and 2-3), and the hand
orientation error every IK run measures.

Orientation errors are checked against PyBullet's forward kinematics and scipy's rotations;
feasibility against HiGHS (scipy's linprog), a solver other than the QP's.
"""

import casadi as cs
import numpy as np
import pybullet as pb
import pytest
from scipy.optimize import linprog
from scipy.spatial.transform import Rotation

import dualarm
from dualarm.contracts.joint_path import JointPath
from dualarm.errors import InvalidArgumentError, StageError
from dualarm.ik.analytic.mc_path import settings_for as mc_settings_for
from dualarm.ik.analytic.mc_path import solve_mc_inverse
from dualarm.ik.metrics import ik_metrics
from dualarm.ik.orientation import orientation_errors, rotation_vector
from dualarm.ik.pose_level.pointwise import solve_pybullet
from dualarm.ik.velocity.pinv import PinvSettings, solve_pinv
from dualarm.ik.velocity.pinv import settings_for as pinv_settings_for
from dualarm.ik.velocity.stack import hand_stack, reference_stack, stacked_reference, start_configuration
from dualarm.ik.velocity.tvgdd import (
    FEASIBILITY_TOLERANCE,
    TvgddSettings,
    build_problem,
    joint_bounds,
    settings_for,
    solve_tvgdd,
)
from dualarm.paths import build_reference
from dualarm.sim.world import load_pybullet_robot
from tests.helpers import still_path_fields

#: Sample stride of the PyBullet checks along a path.
STRIDE = 25
#: TV-GDD's bound scaling nu for the pose triangle: eq (21) lets a joint approach its limit at nu times
#: its distance, and the pose triangle drives the left elbow (whose angle the hand pose fixes on an
#: S-R-S arm) to 0.031 rad from its limit at 5.0 times that distance (measured along MC-Inverse's path).
POSE_NU = 10.0


def pybullet_orientation_errors(
    task, path: JointPath, reference, stride: int = STRIDE
) -> tuple[np.ndarray, np.ndarray]:
    """Rows k = 0, stride, ...: the angle of R_asked^T R_reached per hand [rad], R_reached by PyBullet, R_asked^T
    R_reached by scipy."""
    rows = np.arange(0, len(path), stride)
    angles = np.empty((len(rows), len(path.hands)))
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        for i, k in enumerate(rows):
            q = path.configuration(int(k))
            sim.set_positions(list(q), list(q.values()))
            for j, hand in enumerate(path.hands):
                reached = sim.link_pose(f"{hand}_hand")[:3, :3]
                angles[i, j] = (
                    Rotation.from_matrix(reference.hands[hand].rotation[k]).inv() * Rotation.from_matrix(reached)
                ).magnitude()
    return rows, angles


@pytest.fixture(scope="module")
def triangle():
    """The shipped triangle (five repetitions), its reference, and MC-Inverse's first configuration (on the path start
    in position and orientation)."""
    task = dualarm.load_task("triangle")
    ref = build_reference(task)
    mc = solve_mc_inverse(
        task.robot, build_reference(dualarm.load_task("triangle", 1)), task.initial_q, mc_settings_for(task)
    )
    return task, ref, mc.configuration(0)


@pytest.fixture(scope="module")
def tvgdd_paths(triangle):
    """TV-GDD on the triangle: position task space from the task's initial configuration, pose task space (the task's)
    from MC-Inverse's start with RMP and nu = POSE_NU (see test_pose_mode_with_the_task_defaults_fails_at_the_elbow)."""
    task, ref, start = triangle
    pose_settings = settings_for(task, scheme="rmp", nu=POSE_NU)
    assert pose_settings.task_space == "pose" == task.spec.ik.task_space
    return {
        "position": solve_tvgdd(task.robot, ref, task.initial_q, settings_for(task, task_space="position")),
        "pose": solve_tvgdd(task.robot, ref, start, pose_settings),
    }


@pytest.fixture(scope="module")
def pinv_paths(triangle):
    task, ref, _ = triangle
    assert pinv_settings_for(task).task_space == "pose"
    return {
        space: solve_pinv(task.robot, ref, task.initial_q, pinv_settings_for(task, task_space=space))
        for space in ("position", "pose")
    }


def test_rotation_vector_is_scipys():
    """Seeded rotations of every angle, near 0 and near pi included: the CasADi log map equals scipy's rotation
    vector."""
    M = cs.SX.sym("M", 3, 3)
    log = cs.Function("log", [M], [rotation_vector(M)])
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(600, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate(
        [rng.uniform(0, np.pi, 200), 10.0 ** -rng.uniform(3, 15, 200), np.pi - 10.0 ** -rng.uniform(1, 6, 200)]
    )
    for rotvec in axes * angles[:, None]:
        E = Rotation.from_rotvec(rotvec).as_matrix()
        np.testing.assert_allclose(np.asarray(log(E)).ravel(), rotvec, atol=1e-9)
    assert np.asarray(log(np.eye(3))).ravel().tolist() == [0.0, 0.0, 0.0]
    half_turn = Rotation.from_rotvec([0.0, 0.0, np.pi]).as_matrix()  # the axis's sign is arbitrary at pi
    np.testing.assert_allclose(
        Rotation.from_rotvec(np.asarray(log(half_turn)).ravel()).as_matrix(), half_turn, atol=1e-12
    )


def test_orientation_errors_are_the_angle_between():
    """The angle of A^T B against arccos((trace(A^T B) - 1) / 2), away from 0 and pi where arccos is ill-conditioned."""
    A = Rotation.random(200, random_state=1).as_matrix()
    B = Rotation.random(200, random_state=2).as_matrix()
    expected = np.arccos(np.clip((np.einsum("nij,nij->n", A, B) - 1) / 2, -1, 1))
    keep = (expected > 0.05) & (expected < np.pi - 0.05)
    np.testing.assert_allclose(orientation_errors(A, B)[keep], expected[keep], atol=1e-9)
    assert orientation_errors(A, A).max() < 1e-7


@pytest.mark.integration
def test_pose_stack_rows_match_pybullet_and_finite_differences(triangle):
    """The pose stack of the triangle's hand: 6 rows on 7 joints; its rotation is PyBullet's, and the angular rows of
    its Jacobian are the central differences of the rotation (rotation vectors of R(theta + h e_i) R(theta - h e_i)^T /
    2h, by scipy)."""
    task, _, _ = triangle
    stack = hand_stack(task.robot, task.spec.hands, task.initial_q, task_space="pose")
    assert (stack.n, stack.m, stack.reference_size) == (7, 6, 12)
    lower, upper = task.robot.lower_upper(stack.joint_names)
    theta = np.random.default_rng(3).uniform(lower, upper)
    J = np.asarray(cs.Function("J", [stack.theta], [stack.jacobian])(theta))
    R = np.asarray(stack.rotations(theta))
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(stack.joint_names, theta)
        np.testing.assert_allclose(R, sim.link_pose("left_hand")[:3, :3], atol=1e-6)
    h = 1e-6
    for i in range(stack.n):
        step = np.eye(stack.n)[i] * h
        after, before = (np.asarray(stack.rotations(theta + s)) for s in (step, -step))
        omega = Rotation.from_matrix(after @ before.T).as_rotvec() / (2 * h)
        np.testing.assert_allclose(J[3:, i], omega, atol=1e-7)


@pytest.mark.integration
def test_pose_start_puts_the_hand_on_the_start_pose(triangle):
    """The triangle's initial configuration is off the path start; in pose task space the start configuration puts the
    hand on the first sample's position and orientation (PyBullet), within the joint limits."""
    task, ref, _ = triangle
    stack = reference_stack(task.robot, ref, task.initial_q, False, "pose")
    lower, upper = task.robot.lower_upper(stack.joint_names)
    start = start_configuration(stack, ref, lower, upper)
    assert np.all(start >= lower) and np.all(start <= upper)
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(stack.joint_names, start)
        T = sim.link_pose("left_hand")
    assert np.linalg.norm(T[:3, 3] - ref.hands["left"].position[0]) < 1e-6
    assert Rotation.from_matrix(ref.hands["left"].rotation[0].T @ T[:3, :3]).magnitude() < 1e-6


@pytest.mark.integration
@pytest.mark.parametrize("method", ["tvgdd", "pinv"])
def test_pose_mode_tracks_the_orientation_and_position_mode_does_not(triangle, tvgdd_paths, pinv_paths, method):
    """Along the triangle (every 25th sample, PyBullet): the recorded orientation error is the angle between the asked
    and the reached hand rotations; in pose task space it stays under 2e-3 rad (measured 1.55e-3 rad for TV-GDD, 1.52e-3
    rad for pinv, the lag of the K = 20 feedback) and the hand position under 0.5 mm, while in position task space the
    orientation is up to 2.37 rad off. The metrics say which solved the orientation."""
    task, ref, _ = triangle
    paths = tvgdd_paths if method == "tvgdd" else pinv_paths
    worst = {}
    for space, path in paths.items():
        assert path.task_space == space
        rows, angles = pybullet_orientation_errors(task, path, ref)
        np.testing.assert_allclose(path.hand_orientation_error_rad[rows], angles, atol=1e-6)
        metrics = ik_metrics(path, task.robot)
        assert metrics["ik.orientation_error_max_rad"] == pytest.approx(path.hand_orientation_error_rad.max(), abs=0)
        assert metrics["ik.orientation_error_mean_rad"] == pytest.approx(
            path.hand_orientation_error_rad.mean(), rel=1e-12
        )
        assert metrics["ik.orientation_solved"] == (1.0 if space == "pose" else 0.0)
        assert metrics["ik.position_error_max_m"] < 5e-4
        worst[space] = angles.max()
    assert worst["pose"] < 2e-3 < 1.0 < worst["position"]


def test_pose_mode_stays_within_the_bounds(tvgdd_paths, triangle):
    """Pose TV-GDD keeps every joint within its velocity bounds (eq 25) and position limits."""
    task, _, _ = triangle
    path = tvgdd_paths["pose"]
    assert np.all(path.qd >= path.extras["zeta_lower"] - 1e-9) and np.all(path.qd <= path.extras["zeta_upper"] + 1e-9)
    metrics = ik_metrics(path, task.robot)
    assert metrics["ik.joint_limit_violations"] == 0 and metrics["ik.velocity_limit_violations"] == 0


def test_pose_mode_with_the_papers_nu_fails_at_the_elbow(triangle):
    """With the paper's nu = 2 instead of the triangle's 10 (MVN, the start nearest the initial configuration) the pose
    QP runs out of room at the left elbow: the error names it at its eq (21) bound, and HiGHS finds no velocity within
    the bounds (25) that meets (24) at that step (rebuilt here by the same Euler steps)."""
    task, ref, _ = triangle
    settings = settings_for(task, nu=2.0)
    assert (settings.task_space, settings.scheme, settings.nu) == ("pose", "mvn", 2.0)
    with pytest.raises(
        StageError,
        match=(
            r"infeasible: no joint velocity within the bounds \(25\) meets the hand-velocity equality \(24\)"
            r" \(6 task rows \(pose\) on 7 joints\).*left_elbow at zeta-"
        ),
    ) as caught:
        solve_tvgdd(task.robot, ref, task.initial_q, settings)
    k = caught.value.sample
    stack = reference_stack(task.robot, ref, task.initial_q, False, "pose")
    bounds = joint_bounds(task.robot, stack, settings)
    problem = build_problem(stack, bounds, settings, ref.period_s)
    R, V = stacked_reference(stack, ref)
    theta = theta0 = start_configuration(stack, ref, bounds.lower, bounds.upper)
    for i in range(k):
        velocity, violation = problem.step(theta, ref.t[i], R[i], V[i], theta0)
        assert float(violation) <= FEASIBILITY_TOLERANCE
        theta = theta + ref.period_s * np.asarray(velocity).ravel()
    _, _, J, rhs, lo, hi, _, _ = (np.asarray(x) for x in problem.data(theta, ref.t[k], R[k], V[k], theta0))
    assert (
        linprog(
            np.zeros(stack.n), A_eq=J, b_eq=rhs.ravel(), bounds=list(zip(lo.ravel(), hi.ravel(), strict=True))
        ).status
        == 2
    )  # infeasible
    elbow = stack.joint_names.index("left_elbow")
    assert lo.ravel()[elbow] == pytest.approx(
        settings.nu * (bounds.lower[elbow] - theta[elbow]), abs=1e-12
    )  # eq (21), not the velocity limit
    # with that one bound loosened to the velocity limit, the step is feasible: the elbow is what holds it back
    loose = lo.ravel().copy()
    loose[elbow] = -bounds.velocity[elbow]
    assert (
        linprog(np.zeros(stack.n), A_eq=J, b_eq=rhs.ravel(), bounds=list(zip(loose, hi.ravel(), strict=True))).status
        == 0
    )


@pytest.mark.integration
def test_ball_game_stays_position_only():
    """The ball game keeps the TV-GDD paper's task (m = 3 per hand): its settings, stack and path say position, and its
    orientation is measured (PyBullet) but not solved."""
    task = dualarm.load_task("ball_game")
    ref = build_reference(task)
    settings = settings_for(task)
    assert settings.task_space == pinv_settings_for(task).task_space == task.spec.ik.task_space == "position"
    assert reference_stack(task.robot, ref, task.initial_q, settings.free_waist, settings.task_space).m == 6
    path = solve_tvgdd(task.robot, ref, task.initial_q, settings)
    assert path.task_space == "position"
    rows, angles = pybullet_orientation_errors(task, path, ref, stride=150)
    np.testing.assert_allclose(path.hand_orientation_error_rad[rows], angles, atol=1e-6)
    assert ik_metrics(path, task.robot)["ik.orientation_solved"] == 0.0


@pytest.mark.integration
def test_pose_level_methods_measure_their_orientation_error(triangle):
    """PyBullet's own IK on one triangle repetition: the path's orientation errors are PyBullet FK's, and it counts as
    solving the orientation."""
    task, _, _ = triangle
    one = dualarm.load_task("triangle", 1)
    ref = build_reference(one)
    path = solve_pybullet(one.robot, ref, one.initial_q)
    rows, angles = pybullet_orientation_errors(one, path, ref)
    np.testing.assert_allclose(path.hand_orientation_error_rad[rows], angles, atol=1e-6)
    metrics = ik_metrics(path, one.robot)
    assert (
        metrics["ik.orientation_solved"] == 1.0
        and metrics["ik.orientation_error_max_rad"] == path.hand_orientation_error_rad.max()
    )


def test_task_space_is_checked():
    with pytest.raises(InvalidArgumentError, match="task_space"):
        TvgddSettings(task_space="orientation")
    with pytest.raises(InvalidArgumentError, match="task_space"):
        PinvSettings(task_space="6d")
    N = 3
    fields = still_path_fields(N, period_s=0.1)
    with pytest.raises(InvalidArgumentError, match="task_space"):
        JointPath(**fields, task_space="full")
    with pytest.raises(InvalidArgumentError, match="hand_orientation_error_rad"):
        JointPath(**fields, hand_orientation_error_rad=np.zeros((N, 2)))
    assert np.isnan(JointPath(**fields).hand_orientation_error_rad).all()  # not measured


# --- the shipped pose tasks: their initial configuration and TV-GDD's [gesture] table -----------


def pybullet_limits(sim, names) -> tuple[np.ndarray, np.ndarray]:
    """Position limits [rad] of joints ``names`` as PyBullet reads them from the URDF (getJointInfo)."""
    info = [pb.getJointInfo(sim.body, sim.joint_index[n], physicsClientId=sim.client) for n in names]
    return np.array([i[8] for i in info]), np.array([i[9] for i in info])


def repetition_deviation(path: JointPath, samples_per_repetition: int) -> float:
    """Largest |q(k) - q(k - r n)| [rad] over samples k of repetition r >= 1, n samples per repetition."""
    k = np.arange(samples_per_repetition, len(path))
    return float(np.abs(path.q[k] - path.q[k % samples_per_repetition]).max())


@pytest.fixture(scope="module", params=["triangle", "circle"])
def pose_task(request):
    """A shipped pose task (five repetitions), its reference and MC-Inverse's path on it."""
    task = dualarm.load_task(request.param)
    ref = build_reference(task)
    return task, ref, solve_mc_inverse(task.robot, ref, task.initial_q, mc_settings_for(task))


@pytest.fixture(scope="module")
def pose_tvgdd(pose_task):
    """TV-GDD on the pose task with the task's own settings ([gesture], [ik]) from its initial configuration."""
    task, ref, _ = pose_task
    return solve_tvgdd(task.robot, ref, task.initial_q, settings_for(task))


@pytest.mark.integration
def test_pose_task_starts_on_the_path_at_mc_inverses_configuration(pose_task):
    """The task's initial configuration puts the left hand on the path start in position and orientation (PyBullet FK)
    and is MC-Inverse's first configuration, as the task's notes say: rounded to 1e-6 rad, and the auto arm-angle grid
    is centred on the initial configuration's arm angle, which moves MC-Inverse's path by about 1e-6 rad. The right arm
    is at robot.toml's ready."""
    task, ref, mc = pose_task
    initial = np.array([task.initial_q[n] for n in mc.joint_names])
    np.testing.assert_allclose(initial, mc.q[0], rtol=0, atol=2e-6)
    assert task.initial_q["right_elbow"] == task.robot.configuration("ready", "q0")["right_elbow"] != 0.0
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        T = sim.link_pose("left_hand")
    assert np.linalg.norm(T[:3, 3] - ref.hands["left"].position[0]) < 5e-6
    assert Rotation.from_matrix(ref.hands["left"].rotation[0].T @ T[:3, :3]).magnitude() < 5e-6


@pytest.mark.integration
def test_the_hand_pose_fixes_the_elbow_beyond_the_papers_nu(pose_task):
    """The elbow angle from the reference alone - the law of cosines on the shoulder-wrist distance, with the link
    lengths and the wrist's offset in the hand frame read from PyBullet - is MC-Inverse's at every sample (any IK on the
    pose has it). Eq (21) lets a joint approach its limit at most nu times its distance per second; the path asks the
    elbow for 5.0 (triangle) and 7.3 (circle) times, 0.031 and 0.027 rad from its limit, as the notes say: more than the
    paper's nu = 2, less than the task's."""
    task, ref, mc = pose_task
    elbow = mc.joint_names.index("left_elbow")
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        shoulder = sim.link_pose("left_shoulder_yaw_link")[:3, 3]
        sim.set_positions(mc.joint_names, np.random.default_rng(5).uniform(-1, 1, len(mc.joint_names)))
        at_elbow, wrist, hand = (
            sim.link_pose(link) for link in ("left_forearm", "left_forearm_roll_link", "left_hand")
        )
        lower, upper = pybullet_limits(sim, ["left_elbow"])
    upper_arm, forearm = np.linalg.norm(at_elbow[:3, 3] - shoulder), np.linalg.norm(wrist[:3, 3] - at_elbow[:3, 3])
    wrist_in_hand = hand[:3, :3].T @ (wrist[:3, 3] - hand[:3, 3])
    wrists = ref.hands["left"].position + ref.hands["left"].rotation @ wrist_in_hand
    reach = np.linalg.norm(wrists - shoulder, axis=1)
    bend = np.arccos((reach**2 - upper_arm**2 - forearm**2) / (2 * upper_arm * forearm))  # |elbow angle|, 0 = straight
    side = np.sign(mc.q[0, elbow])
    assert np.all(np.sign(mc.q[:, elbow]) == side)
    np.testing.assert_allclose(np.abs(mc.q[:, elbow]), bend, rtol=0, atol=1e-6)
    room = (-lower[0] if side < 0 else upper[0]) - bend
    needed = float((np.maximum(np.gradient(bend, ref.t), 0.0) / room).max())
    documented = {"triangle": (5.0, 0.031), "circle": (7.3, 0.027)}[task.name]
    assert round(needed, 1) == documented[0] and round(float(room.min()), 3) == documented[1]
    assert 2.0 < needed < task.spec.gesture.nu


@pytest.mark.integration
def test_pose_tvgdd_completes_the_shipped_task_with_its_own_settings(pose_task, pose_tvgdd):
    """TV-GDD with the task's [gesture] and [ik] settings from its initial configuration: every step feasible, the
    joints within PyBullet's limits and within the velocity bounds (25), the hand within 0.5 mm and 2e-3 rad of the
    reference (PyBullet FK, every 25th sample). Where the task sets no goal the bands of eq (19) are the joint limits;
    on the triangle the joints repeat within 0.03 rad (the notes' 0.027)."""
    task, ref, _ = pose_task
    path = pose_tvgdd
    assert path.task_space == "pose" and len(path) == len(ref)
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        lower, upper = pybullet_limits(sim, path.joint_names)
    assert np.all(path.q >= lower) and np.all(path.q <= upper)
    assert np.all(path.qd >= path.extras["zeta_lower"] - 1e-9) and np.all(path.qd <= path.extras["zeta_upper"] + 1e-9)
    rows, angles = pybullet_orientation_errors(task, path, ref)
    assert angles.max() < 2e-3 and path.hand_error_m.max() < 5e-4
    goals = {**task.spec.gesture.goal_lower, **task.spec.gesture.goal_upper}
    free = [i for i, n in enumerate(path.joint_names) if n not in goals]
    np.testing.assert_allclose(
        path.extras["theta_lower"][:, free], np.broadcast_to(lower[free], (len(path), len(free))), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        path.extras["theta_upper"][:, free], np.broadcast_to(upper[free], (len(path), len(free))), rtol=0, atol=1e-12
    )
    if task.name == "triangle":
        per_repetition = round(sum(m.duration_s for m in task.spec.moves) / ref.period_s)
        assert repetition_deviation(path, per_repetition) < 0.03


def test_triangle_mvn_without_the_shoulder_yaw_goal_drifts_out_of_room(triangle):
    """The triangle's [gesture] without its one goal: MVN drifts along the self-motion (the shoulder yaw rises by more
    than 0.4 rad in each of the first two triangles) and a step of the third triangle is infeasible; HiGHS confirms it
    at that step (rebuilt by the same Euler steps)."""
    task, ref, _ = triangle
    settings = settings_for(task, goal_upper={})
    assert settings.scheme == "mvn" and task.spec.gesture.goal_upper == {
        "left_shoulder_yaw": task.initial_q["left_shoulder_yaw"]
    }
    with pytest.raises(StageError, match=r"infeasible") as caught:
        solve_tvgdd(task.robot, ref, task.initial_q, settings)
    k = caught.value.sample
    assert ref.rep[k] == 2
    stack = reference_stack(task.robot, ref, task.initial_q, False, "pose")
    bounds = joint_bounds(task.robot, stack, settings)
    problem = build_problem(stack, bounds, settings, ref.period_s)
    R, V = stacked_reference(stack, ref)
    theta = theta0 = start_configuration(stack, ref, bounds.lower, bounds.upper)
    yaw = stack.joint_names.index("left_shoulder_yaw")
    starts = {}
    for i in range(k):
        if ref.rep[i] != ref.rep[i - 1] or i == 0:
            starts[int(ref.rep[i])] = theta[yaw]
        velocity, violation = problem.step(theta, ref.t[i], R[i], V[i], theta0)
        assert float(violation) <= FEASIBILITY_TOLERANCE
        theta = theta + ref.period_s * np.asarray(velocity).ravel()
    assert starts[1] - starts[0] > 0.4 and starts[2] - starts[1] > 0.4
    _, _, J, rhs, lo, hi, _, _ = (np.asarray(x) for x in problem.data(theta, ref.t[k], R[k], V[k], theta0))
    assert (
        linprog(
            np.zeros(stack.n), A_eq=J, b_eq=rhs.ravel(), bounds=list(zip(lo.ravel(), hi.ravel(), strict=True))
        ).status
        == 2
    )  # infeasible


@pytest.mark.integration
def test_pose_tvgdd_from_ready_starts_on_another_branch_and_fails(pose_task):
    """Why the pose tasks start on the path: from robot.toml's ready, TV-GDD (the task's settings) starts on the pose
    solution nearest ready, which puts the hand on the path start too (PyBullet) but on another branch than MC-Inverse's
    (the wrist pitch of the other sign), and its QP runs out of room within the first repetition."""
    task, ref, mc = pose_task
    settings = settings_for(task)
    stack = reference_stack(task.robot, ref, "ready", False, "pose")
    lower, upper = task.robot.lower_upper(stack.joint_names)
    start = start_configuration(stack, ref, lower, upper)
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(stack.joint_names, start)
        T = sim.link_pose("left_hand")
    assert np.linalg.norm(T[:3, 3] - ref.hands["left"].position[0]) < 1e-6
    wrist = stack.joint_names.index("left_wrist_pitch")
    assert np.sign(start[wrist]) != np.sign(mc.q[0, mc.joint_names.index("left_wrist_pitch")])
    with pytest.raises(StageError, match=r"infeasible") as caught:
        solve_tvgdd(task.robot, ref, "ready", settings)
    assert ref.rep[caught.value.sample] == 0
