"""SEW-angle IK on the Franka Panda (3R-R-2R-R, not S-R-S): every candidate against the project's double-precision FK, PyBullet's FK, the paper's form of the stereographic SEW angle, and IK-Geo (the `ik-geo` package) with joint 7 fixed."""

import ik_geo
import numpy as np
import pybullet as pb
import pytest

from dualarm.errors import NotSRSError
from dualarm.ik.sew import NotSewError, SewAngle, sew_chain, solve
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import load_robot
from tests.conftest import HUMANOID, REPO, pybullet_urdf

PANDA = REPO / "robots" / "panda"
#: The stereographic SEW angle: singular half-line straight down from the shoulder (into the Panda's base), reference up.
STEREO = SewAngle(reference=(0.0, 0.0, 1.0), singular=(0.0, 0.0, -1.0))


@pytest.fixture(scope="module")
def panda():
    robot = load_robot(PANDA)
    chain = robot.hand_chain("right")
    lower, upper = robot.lower_upper(chain.joint_names)
    Q = np.random.default_rng(11).uniform(lower, upper, (60, 7))
    return robot, chain, sew_chain(chain), Q


def _psi(arm, sew, q):
    return float(sew.angle(*(x[0] for x in arm.points(q[None]))))


def _wrapped(a):
    return np.abs(np.angle(np.exp(1j * np.asarray(a))))


def test_the_product_of_exponentials_is_the_urdf_chain(panda):
    """The POE poses equal the chain's FK (1e-11) at random configurations; S, E, C, W sit on the axes that define them, as PyBullet places the joints at q = 0; the offsets are the Panda's (0.088 m at the wrist, 0.0825 m at the elbow)."""
    _, chain, arm, Q = panda
    assert np.abs(arm.poses(Q) - ChainKinematics.of(chain).poses(Q)).max() < 1e-11
    with pybullet_urdf(PANDA / "panda.urdf") as sim:  # at q = 0
        on = (arm.shoulder, arm.shoulder, arm.shoulder, arm.elbow, arm.crossing, arm.crossing, arm.wrist)
        for name, point in zip(chain.joint_names, on):
            info = pb.getJointInfo(sim.body, sim.joint[name], physicsClientId=sim.client)
            T = sim.frame(info[12].decode())  # the joint frame is its child link's
            axis = T[:3, :3] @ np.asarray(info[13])
            assert np.linalg.norm(np.cross(axis, point - T[:3, 3])) < 1e-6, name
    assert np.linalg.norm(arm.wrist - arm.crossing) == pytest.approx(0.088, abs=1e-9)
    assert np.linalg.norm(arm.elbow - arm.shoulder) == pytest.approx(np.hypot(0.316, 0.0825), abs=1e-9)


def test_the_stereographic_angle_is_the_papers_formula():
    """psi = atan2(n_sew . (w x n_ref), n_sew . n_ref), n_sew = W x E, n_ref = (w - e_t) x e_r (Elias and Wen), on random points."""
    rng = np.random.default_rng(0)
    S, E, W = rng.normal(size=(3, 200, 3))
    t, r = np.array(STEREO.singular), np.array(STEREO.reference)
    w = (W - S) / np.linalg.norm(W - S, axis=1, keepdims=True)
    n_sew = np.cross(W - S, E - S)
    n_sew /= np.linalg.norm(n_sew, axis=1, keepdims=True)
    n_ref = np.cross(w - t, r)
    n_ref /= np.linalg.norm(n_ref, axis=1, keepdims=True)
    expected = np.arctan2(np.einsum("ni,ni->n", n_sew, np.cross(w, n_ref)), np.einsum("ni,ni->n", n_sew, n_ref))
    assert _wrapped(STEREO.angle(S, E, W) - expected).max() < 1e-12


def test_every_candidate_reproduces_the_pose_and_angle_and_one_is_the_configuration(panda):
    """60 random configurations within the limits: at each one's own pose and SEW angle, one candidate is that configuration (1e-6: near a double root it is determined only so far), and every candidate reproduces the pose by the chain's FK to 1e-9 m / 1e-9 and the angle to 1e-9 rad."""
    _, chain, arm, Q = panda
    kin = ChainKinematics.of(chain)
    counts = []
    for q in Q:
        T, psi = kin.pose(q), _psi(arm, STEREO, q)
        found = solve(arm, T, psi, STEREO)
        counts.append(len(found.q))
        assert _wrapped(found.q - q).max(axis=1).min() < 1e-6
        got = kin.poses(found.q)
        assert np.linalg.norm(got[:, :3, 3] - T[:3, 3], axis=1).max() < 1e-9
        assert np.abs(got[:, :3, :3] - T[:3, :3]).max() < 1e-9
        assert _wrapped(STEREO.angle(*arm.points(found.q)) - psi).max() < 1e-9
        assert len(np.unique(np.round(found.q, 6), axis=0)) == len(found.q)  # no solution twice
    assert max(counts) <= 16 and min(counts) >= 2  # solutions come in shoulder pairs


def test_candidates_agree_with_pybullet(panda):
    """PyBullet's hand frame at every candidate of 10 poses equals the asked pose (1e-6: PyBullet reports float32)."""
    _, chain, arm, Q = panda
    kin = ChainKinematics.of(chain)
    with pybullet_urdf(PANDA / "panda.urdf") as sim:
        for q in Q[:10]:
            T = kin.pose(q)
            for candidate in solve(arm, T, _psi(arm, STEREO, q), STEREO).q:
                sim.set(chain.joint_names, candidate)
                reached = sim.frame(chain.tip)
                assert np.linalg.norm(reached[:3, 3] - T[:3, 3]) < 1e-6
                assert np.abs(reached[:3, :3] - T[:3, :3]).max() < 1e-6


def test_ik_geo_with_joint_7_fixed_finds_the_same_solutions(panda):
    """IK-Geo (`ik-geo`): with q7 fixed at a candidate's, the Panda's joints 1-6 reversed are its spherical_two_intersecting robot (joints 6, 5 meet; 3, 2, 1 meet at the shoulder). Every candidate's q1..q6 is among its solutions, and every exact solution it finds at that q7 with our SEW angle is among ours."""
    _, chain, arm, Q = panda
    kin = ChainKinematics.of(chain)
    S, E, C = arm.shoulder, arm.elbow, arm.crossing
    checked = 0
    for q in Q[:20]:
        T, psi = kin.pose(q), _psi(arm, STEREO, q)
        ours = solve(arm, T, psi, STEREO).q
        for candidate in ours:
            R67 = _rot(arm.axes[6], candidate[6])
            tool = (arm.wrist - C) + R67 @ arm.tool  # C -> tip with q7 fixed
            end = C + tool  # the 6R's tip at q = 0
            H = -arm.axes[:6][::-1]
            P = np.array([C - end, np.zeros(3), E - C, S - E, np.zeros(3), np.zeros(3), -S])
            robot = ik_geo.Robot.spherical_two_intersecting(H.tolist(), P.tolist())
            R06 = T[:3, :3] @ arm.tool_rotation.T @ R67.T
            # the reversed chain's pose is the inverse; ik-geo reads a rotation's rows as columns, so R06 (= (R06^T)^T) is passed as is
            theirs = [np.array(s)[::-1] for s, least_squares in robot.get_ik(R06.tolist(), (-R06.T @ T[:3, 3]).tolist()) if not least_squares]
            assert min(_wrapped(t - candidate[:6]).max() for t in theirs) < 1e-6
            for t in theirs:
                full = np.append(t, candidate[6])
                if _wrapped(_psi(arm, STEREO, full) - psi) < 1e-6:
                    assert _wrapped(ours - full).max(axis=1).min() < 1e-6
            checked += 1
    assert checked >= 40


def _rot(k, t):
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def test_refusals_name_the_chain_and_why():
    """An S-R-S arm is MC-Inverse's; a chain without 7 joints is no 7R arm: one line each, a NotSRSError (the CLI's exit 2)."""
    humanoid = load_robot(HUMANOID)
    with pytest.raises(NotSewError, match="left_arm' is S-R-S .*use mc-inverse"):
        sew_chain(humanoid.hand_chain("left"))
    panda = load_robot(PANDA)
    with pytest.raises(NotSRSError, match="has 6 movable joints; the SEW solver needs 7 revolute joints"):
        sew_chain(panda.chain_between("panda_link1", panda.hand_chain("right").tip))


def test_ik_sew_command_prints_every_solution_as_json(panda):
    """`dualarm ik sew panda --arm right --pose ... --sew-angle PSI --json` at the pose and SEW angle of a configuration inside the limits: that configuration is among the candidates and marked valid, every candidate's reported FK errors are below 1e-9, and valid means inside robot.toml's limits."""
    import json

    from scipy.spatial.transform import Rotation
    from typer.testing import CliRunner

    from dualarm.cli import app

    robot, chain, arm, Q = panda
    q = Q[0]
    T = ChainKinematics.of(chain).pose(q)  # the chain's base is the Panda's root link: robot frame = chain frame
    pose = [*T[:3, 3], *Rotation.from_matrix(T[:3, :3]).as_euler("xyz")]
    psi = _psi(arm, STEREO, q)
    result = CliRunner().invoke(app, ["ik", "sew", "panda", "--arm", "right", "--pose", *(repr(float(v)) for v in pose), "--sew-angle", repr(psi), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["singular"] == [0.0, 0.0, -1.0] and data["reference"] == [0.0, 0.0, 1.0]
    candidates = data["candidates"]
    mine = [c for c in candidates if _wrapped(np.array(c["q"]) - q).max() < 1e-6]
    assert len(mine) == 1 and mine[0]["valid"] and mine[0]["reason"] == "valid"
    assert max(c["position_error_m"] for c in candidates) < 1e-9 and max(c["orientation_error_rad"] for c in candidates) < 1e-9
    lower, upper = robot.lower_upper(chain.joint_names)
    for c in candidates:
        inside = bool(np.all((lower <= c["q"]) & (np.array(c["q"]) <= upper)))
        assert c["valid"] is inside


def test_ik_sew_command_refuses_in_one_line():
    """An S-R-S arm, and a pose out of reach, exit 2 with one line and no traceback."""
    from typer.testing import CliRunner

    from dualarm.cli import app

    runner = CliRunner()
    for args, needle in (
        (["ik", "sew", "humanoid", "--arm", "left", "--pose", "0.3", "0.27", "1.0", "0", "0", "0", "--sew-angle", "0.5"], "is S-R-S"),
        (["ik", "sew", "panda", "--arm", "right", "--pose", "2", "0", "0.5", "3.1416", "0", "0", "--sew-angle", "0.5"], "no solution at psi = 0.5 rad"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 2, result.output
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and needle in lines[0] and "Traceback" not in result.output
