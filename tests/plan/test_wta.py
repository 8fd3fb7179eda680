"""Workspace Target Areas (dualarm.plan.wta, Li & Liang eqs 21-31) against hand-computed
values and scipy's own rotations."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.model.poses import pose_matrix
from dualarm.plan.wta import Wta, displacement, pose_vector, sample_hand_pose, sampling_weights
from dualarm.tasks import load_task
from tests.helpers import TASKS

PI = np.pi


def transform(position, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A 4x4 pose built directly from scipy (extrinsic x-y-z), independent of pose_matrix."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    T[:3, 3] = position
    return T


# --- eq (25) -------------------------------------------------------------------------------------

RPYS = [
    (0.0, 0.0, 0.0),
    (0.3, -0.2, 0.1),
    (-2.5, 1.2, 3.0),
    (3.0, -1.4, -3.0),
    (PI / 2, 0.0, 0.0),
    (-1.0, 0.5, -PI / 2),
    (0.0, 1.5, 0.0),
]


@pytest.mark.parametrize("rpy", RPYS)
def test_pose_vector_recovers_position_and_rpy(rpy):
    p = np.array([0.4, -0.1, 0.93])
    expected = np.r_[p, rpy]
    assert np.allclose(pose_vector(pose_matrix(p, rpy)), expected, atol=1e-9)
    assert np.allclose(pose_vector(transform(p, rpy)), expected, atol=1e-9)


def test_pose_vector_matches_scipy_euler_on_random_rotations_batched():
    rng = np.random.default_rng(25)
    R = Rotation.random(200, random_state=rng)
    T = np.tile(np.eye(4), (200, 1, 1))
    T[:, :3, :3] = R.as_matrix()
    T[:, :3, 3] = rng.normal(size=(200, 3))
    v = pose_vector(T)
    assert v.shape == (200, 6)
    assert np.allclose(v[:, :3], T[:, :3, 3])
    # scipy's extrinsic "xyz" angles put pitch in [-pi/2, pi/2], the convention of eq (25)
    assert np.allclose(v[:, 3:], R.as_euler("xyz"), atol=1e-9)


# --- eq (26) -------------------------------------------------------------------------------------

BOUNDS = np.array([[0.0, 1.0], [-1.0, -0.5], [2.0, 2.0], [-0.1, 0.1], [0.0, 0.5], [-3.0, 3.0]])


@pytest.mark.parametrize(
    ("x", "expected"),
    [
        ([-0.5, -0.75, 2.0, 0.0, 0.25, 0.0], [-0.5, 0, 0, 0, 0, 0]),  # below in x only
        ([1.25, -0.75, 2.0, 0.0, 0.25, 0.0], [0.25, 0, 0, 0, 0, 0]),  # above in x only
        ([0.5, -0.75, 2.0, 0.0, 0.25, 0.0], [0, 0, 0, 0, 0, 0]),  # inside
        ([0.0, -1.0, 2.0, 0.1, 0.5, -3.0], [0, 0, 0, 0, 0, 0]),  # on the bounds
        ([2.0, 0.0, 1.5, 0.3, -0.2, 3.5], [1.0, 0.5, -0.5, 0.2, -0.2, 0.5]),  # outside everywhere
    ],
)
def test_displacement_hand_computed(x, expected):
    assert np.allclose(displacement(np.array(x), BOUNDS), expected, atol=1e-12)


def test_displacement_batched():
    x = np.array([[-0.5, -0.75, 2.0, 0.0, 0.25, 0.0], [2.0, 0.0, 1.5, 0.3, -0.2, 3.5]])
    assert np.allclose(displacement(x, BOUNDS), [[-0.5, 0, 0, 0, 0, 0], [1.0, 0.5, -0.5, 0.2, -0.2, 0.5]], atol=1e-12)


# --- Wta.distance (eqs 22-26) --------------------------------------------------------------------


@pytest.fixture
def area() -> Wta:
    return Wta(
        name="hand_made",
        hand="left",
        reference=transform([0.4, 0.0, 0.9]),
        offset=transform([0.0, 0.1, 0.0], [PI / 2, 0.0, 0.0]),
        bounds=np.array([[-0.02, 0.02], [0, 0], [0, 0], [0, 0], [0, 0], [-0.4, 0.4]], dtype=float),
    )


@pytest.mark.parametrize(
    ("position", "rpy", "expected"),
    [
        ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0),
        ([0.01, 0.0, 0.0], [0.0, 0.0, 0.3], 0.0),  # inside the x and yaw bands
        ([0.05, 0.0, 0.0], [0.0, 0.0, 0.0], 0.03),  # 0.05 - 0.02
        ([-0.07, 0.0, 0.0], [0.0, 0.0, 0.0], 0.05),  # -0.07 - (-0.02)
        ([0.0, 0.0, 0.0], [0.0, 0.0, 0.5], 0.1),  # 0.5 - 0.4
        ([0.0, 0.0, 0.0], [0.0, 0.0, -0.7], 0.3),
        ([0.0, 0.02, 0.0], [0.0, 0.0, 0.0], 0.02),  # y fixed at 0
        ([0.0, 0.0, -0.04], [0.0, 0.0, 0.0], 0.04),
        ([0.05, 0.0, 0.0], [0.0, 0.0, 0.5], np.hypot(0.03, 0.1)),
        ([0.0, 0.0, 0.0], [0.3, 0.2, 0.0], np.hypot(0.3, 0.2)),
        ([0.05, 0.02, 0.0], [0.0, 0.1, 0.6], np.sqrt(0.03**2 + 0.02**2 + 0.1**2 + 0.2**2)),
    ],
)
def test_distance_hand_computed(area, position, rpy, expected):
    hand = area.reference @ transform(position, rpy) @ area.offset
    assert area.distance(hand) == pytest.approx(expected, abs=1e-12)


def test_distance_batched(area):
    hands = np.stack(
        [
            area.reference @ transform(p, r) @ area.offset
            for p, r in [([0, 0, 0], [0, 0, 0]), ([0.05, 0, 0], [0, 0, 0]), ([0, 0, 0], [0, 0, 0.5])]
        ]
    )
    assert np.allclose(area.distance(hands), [0.0, 0.03, 0.1], atol=1e-12)


def test_hand_frame_not_the_carried_frame(area):
    """The hand at the WTA's reference itself carries the frame (^WTA T_e)^-1: rolled by -pi/2
    and at -Rx(-pi/2) [0, 0.1, 0] = [0, 0, 0.1] m (by hand), so 0.1 m off in z; the offset really is removed
    before comparing with the bounds."""
    assert area.distance(area.reference) == pytest.approx(np.hypot(0.1, PI / 2), abs=1e-12)


# --- eqs (27)-(29) -------------------------------------------------------------------------------


def test_hand_pose_then_carried_vector_round_trip():
    rng = np.random.default_rng(29)
    bounds = np.array([[-0.1, 0.1], [-0.2, 0.2], [0.0, 0.3], [-3.0, 3.0], [-1.4, 1.4], [-3.0, 3.0]])
    for _ in range(20):
        reference = transform(rng.normal(size=3), Rotation.random(random_state=rng).as_euler("xyz"))
        offset = transform(rng.normal(scale=0.1, size=3), Rotation.random(random_state=rng).as_euler("xyz"))
        wta = Wta("random", "right", reference, offset, bounds)
        for _ in range(10):
            x = bounds[:, 0] + rng.random(6) * (bounds[:, 1] - bounds[:, 0])
            hand = wta.hand_pose(x)
            assert np.allclose(hand, reference @ transform(x[:3], x[3:]) @ offset, atol=1e-12)
            assert np.allclose(wta.carried_vector(hand), x, atol=1e-9)
            assert wta.distance(hand) == pytest.approx(0.0, abs=1e-9)


def test_sample_vector_uniform_in_the_box(area):
    rng = np.random.default_rng(27)
    bounds = np.array([[-0.02, 0.02], [0.0, 0.0], [-0.01, 0.03], [0.1, 0.5], [-1.0, 1.0], [-0.4, 0.4]])
    wta = Wta("box", "left", area.reference, area.offset, bounds)
    n = 2000
    X = np.array([wta.sample_vector(rng) for _ in range(n)])
    assert X.shape == (n, 6)
    assert np.all(X >= bounds[:, 0]) and np.all(X <= bounds[:, 1])
    width = bounds[:, 1] - bounds[:, 0]
    sigma = width / np.sqrt(12 * n)  # standard error of the mean of a uniform
    assert np.all(np.abs(X.mean(axis=0) - bounds.mean(axis=1)) <= 5 * sigma + 1e-15)
    # the spread is a uniform's too (not, say, all samples at the centre)
    assert np.allclose(X.std(axis=0), width / np.sqrt(12), rtol=0.1, atol=1e-15)


# --- eqs (30)-(31) -------------------------------------------------------------------------------


def boxed(name: str, widths, weight: float = 1.0, centre=(0.0, 0.0, 0.0)) -> Wta:
    """An area around ``centre`` whose six widths are ``widths``."""
    half = np.asarray(widths, dtype=float) / 2
    return Wta(name, "left", transform(centre), np.eye(4), np.stack([-half, half], axis=1), weight)


def test_sampling_weights_hand_computed():
    a = boxed("a", [0.04, 0, 0.02, 0, 0, 0.04])  # widths sum 0.1
    b = boxed("b", [0.1, 0.1, 0, 0, 0, 0.1])  # widths sum 0.3
    assert np.allclose(sampling_weights([a, b]), [0.25, 0.75])
    a2 = boxed("a", [0.04, 0, 0.02, 0, 0, 0.04], weight=2.0)  # 0.2 vs 0.3
    assert np.allclose(sampling_weights([a2, b]), [0.4, 0.6])
    assert np.allclose(sampling_weights([a]), [1.0])


def test_sampling_weights_single_poses_are_equal():
    poses = [boxed(n, [0] * 6) for n in "abc"]
    assert np.allclose(sampling_weights(poses), [1 / 3, 1 / 3, 1 / 3])
    # a single pose next to an area with width gets no weight (eq 31)
    assert np.allclose(sampling_weights([boxed("p", [0] * 6), boxed("q", [0.1] * 6)]), [0.0, 1.0])


def test_sample_hand_pose_draws_areas_by_weight():
    """Two disjoint areas 1 m apart with weights 0.25 / 0.75: the draw frequencies within 5
    binomial standard deviations, and every pose inside the area returned (and not the other)."""
    a = boxed("a", [0.04, 0, 0.02, 0, 0, 0.04], centre=(0.0, 0.0, 0.0))
    b = boxed("b", [0.1, 0.1, 0, 0, 0, 0.1], centre=(1.0, 0.0, 0.0))
    rng = np.random.default_rng(31)
    n, first = 4000, 0
    for _ in range(n):
        chosen, pose = sample_hand_pose([a, b], rng)
        other = b if chosen is a else a
        assert chosen.distance(pose) == pytest.approx(0.0, abs=1e-9)
        assert other.distance(pose) > 0.5
        first += chosen is a
    sd = np.sqrt(n * 0.25 * 0.75)
    assert abs(first - 0.25 * n) <= 5 * sd


def test_sample_hand_pose_single_area(area):
    rng = np.random.default_rng(0)
    for _ in range(20):
        chosen, pose = sample_hand_pose([area], rng)
        assert chosen is area and area.distance(pose) == pytest.approx(0.0, abs=1e-9)


# --- Wta.of on a task file -----------------------------------------------------------------------


@pytest.mark.integration
def test_wta_of_bowl_grasp_matches_the_file():
    path = TASKS / "bowl_grasp.toml"
    tables = tomllib.loads(path.read_text())["wta"]
    areas = [Wta.of(spec) for spec in load_task(path).spec.wta]
    assert [a.name for a in areas] == [t["name"] for t in tables] == ["bowl_left", "bowl_right"]
    for wta, table in zip(areas, tables, strict=True):
        assert wta.hand == table["hand"]
        for attr in ("reference", "offset"):
            pose = table[attr]
            expected = transform(pose["position"], pose.get("rpy", (0.0, 0.0, 0.0)))
            assert np.allclose(getattr(wta, attr), expected, atol=1e-12)
        assert np.array_equal(wta.bounds, np.array(table["bounds"], dtype=float))
        assert wta.weight == table.get("weight", 1.0)
    # the two hands approach the bowl from either side: offsets 0.125 m along +y and -y
    left, right = areas
    assert np.allclose(left.hand_pose(np.zeros(6))[:3, 3], [0.4, 0.125, 0.95])
    assert np.allclose(right.hand_pose(np.zeros(6))[:3, 3], [0.4, -0.125, 0.95])
