"""The planners' collision checker (dualarm.plan.collision) against independent queries:
PyBullet's getClosestPoints on the UN-inflated robot, the reference checker (PyBullet's narrow phase
on the inflated robot), analytic capsule distances from the URDF, and the URDF text itself."""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.errors import StageError
from dualarm.model.robot import load_robot
from dualarm.plan.checker import bisection_order, inflated_urdf
from dualarm.plan.collision import CollisionChecker
from dualarm.plan.distances import distance_functions
from dualarm.plan.pybullet_checker import PyBulletChecker
from dualarm.plan.shapes import BOX_ROUNDING_M
from dualarm.sim.world import TOUCHING_M, add_environment, load_pybullet_robot, pb
from dualarm.tasks import load_task
from dualarm.tasks.schema import EnvironmentObject
from tests.helpers import HUMANOID, TASKS

#: Configurations whose nearest distance is this close to a threshold are boundary cases [m].
BOUNDARY_M = 1e-4
#: Agreement of the checker's distances with PyBullet's closest points [m]: the same geometry, both
#: exact (PyBullet reports link poses in single precision, ~1e-7 m).
DISTANCE_M = 1e-6


@pytest.fixture(scope="module")
def task():
    return load_task(TASKS / "bowl_grasp.toml")


@pytest.fixture(scope="module")
def names(task):
    names = task.robot.joint_names
    assert len(names) == 17
    return names


@pytest.fixture(scope="module")
def reference(task):
    """The un-inflated robot (no self-collision flag needed: getClosestPoints ignores filters)
    and the task's objects in their own client; yields (sim, body id -> object name)."""
    sim = load_pybullet_robot(task.robot.urdf.path)
    objects = add_environment(sim, task.spec.environment)
    yield sim, objects
    sim.close()


def make_checker(task, names, margin_m, **kwargs) -> CollisionChecker:
    return CollisionChecker(
        task.robot, names, {}, task.spec.environment, task.spec.expected_contacts, margin_m=margin_m, **kwargs
    )


def urdf_collisions(task) -> dict[str, tuple[np.ndarray, str, dict[str, float]]]:
    """Read from the URDF text: link -> (4x4 collision origin in the link frame, shape tag,
    attributes as floats)."""
    out = {}
    for link in ET.parse(task.robot.urdf.path).getroot().iter("link"):
        collisions = link.findall("collision")
        if not collisions:
            continue
        (collision,) = collisions
        origin = collision.find("origin")
        T = np.eye(4)
        if origin is not None:
            T[:3, :3] = Rotation.from_euler("xyz", [float(v) for v in origin.get("rpy", "0 0 0").split()]).as_matrix()
            T[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
        (shape,) = list(collision.find("geometry"))
        out[link.get("name")] = (T, shape.tag, {k: float(v) for k, v in shape.attrib.items()})
    return out


def link_frame(sim, link: str) -> np.ndarray:
    """The URDF link frame in the world, from getLinkState's worldLinkFrame (indices 4, 5)."""
    state = pb.getLinkState(sim.body, sim.link_index[link], computeForwardKinematics=True, physicsClientId=sim.client)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(state[5]).as_matrix()
    T[:3, 3] = state[4]
    return T


def nearest(sim, body_b: int, link_a: int, link_b: int, within: float) -> float | None:
    """PyBullet's nearest distance between two links (or a link and a body's base), None if
    farther than ``within`` [m]."""
    points = pb.getClosestPoints(sim.body, body_b, within, link_a, link_b, physicsClientId=sim.client)
    return min(p[8] for p in points) if points else None


def reference_contacts(sim, objects, names, q, margin_m, unchecked, allowed):
    """Independent answer on the un-inflated robot at ``q``: {pair: threshold - distance} for the
    checked pairs closer than their threshold (margin to objects, twice the margin between
    links), pairs keyed (link, object) or sorted (link, link); and whether any checked pair is
    within BOUNDARY_M of its threshold."""
    sim.set_positions(names, q)
    solid = sorted(sim.collision_links())
    link = {i: n for n, i in sim.link_index.items()}
    found, boundary = {}, False
    for body, obj in objects.items():
        for a in solid:
            if (link[a], obj) in allowed:
                continue
            d = nearest(sim, body, a, -1, margin_m + 0.01)
            if d is not None:
                boundary |= abs(d - margin_m) < BOUNDARY_M
                if d < margin_m:
                    found[(link[a], obj)] = margin_m - d
    for a, b in itertools.combinations(solid, 2):
        pair = tuple(sorted((link[a], link[b])))
        if pair in unchecked:
            continue
        d = nearest(sim, sim.body, a, b, 2 * margin_m + 0.01)
        if d is not None:
            boundary |= abs(d - 2 * margin_m) < BOUNDARY_M
            if d < 2 * margin_m:
                found[pair] = 2 * margin_m - d
    return found, boundary


def as_found(sim, contacts) -> dict[tuple[str, str], float]:
    """The checker's contacts keyed like :func:`reference_contacts`."""
    out = {}
    for c in contacts:
        assert c.a in sim.link_index, c  # the first name is always a robot link
        key = tuple(sorted((c.a, c.b))) if c.b in sim.link_index else (c.a, c.b)
        assert key not in out, c  # one contact per pair
        out[key] = c.depth_m
    return out


def allowed_pairs(task) -> set[tuple[str, str]]:
    return {tuple(p) for p in task.spec.expected_contacts}


# --- the checker against getClosestPoints on the un-inflated robot -------------------------------


@pytest.mark.integration
@pytest.mark.parametrize("margin_m", [0.0, 0.01])
def test_checker_agrees_with_closest_points_on_the_uninflated_robot(task, names, reference, margin_m):
    sim, objects = reference
    # the reference considers every link with geometry, as the URDF has them
    assert {n for n, i in sim.link_index.items() if i in sim.collision_links()} == set(urdf_collisions(task))
    lower, upper = task.robot.lower_upper(names)
    rng = np.random.default_rng(2024)
    allowed = allowed_pairs(task)
    n, boundary, colliding, kinds = 300, 0, 0, set()
    with make_checker(task, names, margin_m) as checker:
        for k in range(n):
            q = lower + rng.random(len(names)) * (upper - lower)
            expected, near = reference_contacts(sim, objects, names, q, margin_m, checker.unchecked_pairs, allowed)
            free = checker.free(q)
            contacts = checker.contacts(q)
            got = as_found(sim, contacts)
            if near:
                boundary += 1
                continue
            assert free == (not expected), (k, expected)
            assert set(got) == set(expected), (k, set(got) ^ set(expected))
            for pair, depth in expected.items():
                assert got[pair] == pytest.approx(depth, abs=1e-6), (k, pair)
            assert [c.depth_m for c in contacts] == sorted((c.depth_m for c in contacts), reverse=True)
            colliding += not free
            kinds |= {"self" if pair[1] in sim.link_index else "object" for pair in expected}
        assert checker.checks == 2 * n
    assert boundary <= 3
    # not vacuous: both outcomes, and both kinds of contact, are common
    assert 0.2 * n <= colliding <= 0.8 * n
    assert kinds == {"self", "object"}


@pytest.mark.integration
@pytest.mark.parametrize("margin_m", [0.0, 0.01, 0.02])
def test_unchecked_pairs_are_parents_and_touching_neighbours(task, names, reference, margin_m):
    """The unchecked pairs, rebuilt from the URDF tree and the un-inflated distances at the zero
    configuration: a link and its nearest ancestor with geometry when that is its direct parent,
    or when they are joined through bare links and are within TOUCHING_M of each other."""
    sim, _ = reference
    root = ET.parse(task.robot.urdf.path).getroot()
    parent = {j.find("child").get("link"): j.find("parent").get("link") for j in root.iter("joint")}
    solid = set(urdf_collisions(task))
    sim.set_positions(names, np.zeros(len(names)))
    expected = set()
    for link in solid:
        up, through_bare = parent.get(link), False
        while up is not None and up not in solid:
            up, through_bare = parent.get(up), True
        if up is None:
            continue
        if through_bare and nearest(sim, sim.body, sim.link_index[link], sim.link_index[up], TOUCHING_M) is None:
            continue
        expected.add(tuple(sorted((link, up))))
    assert ("left_upper_arm", "torso") not in expected and ("pelvis", "torso") in expected
    with make_checker(task, names, margin_m) as checker:
        assert checker.unchecked_pairs == expected


# --- the closed-form checker's own distances, batches and PyBullet fallback ----------------------

#: Besides the bowl grasp's objects: a tilted box, a sphere and a tilted cylinder in the arms' reach.
EXTRA = [
    EnvironmentObject(
        name="crate",
        shape="box",
        size_m=(0.12, 0.3, 0.08),
        pose={"position": (0.3, 0.25, 1.15), "rpy": (0.3, -0.5, 0.9)},
    ),
    EnvironmentObject(name="ball", shape="sphere", radius_m=0.06, pose={"position": (0.25, -0.3, 1.2)}),
    EnvironmentObject(
        name="post",
        shape="cylinder",
        radius_m=0.03,
        height_m=0.3,
        pose={"position": (0.35, -0.15, 1.1), "rpy": (0.4, 0.2, 0.0)},
    ),
]


def pybullet_distance(sim, bodies: dict[str, int], a: str, b: str) -> float:
    """PyBullet's signed distance between link ``a`` and link or object ``b`` (getClosestPoints) [m]."""
    other, link = (bodies[b], -1) if b in bodies else (sim.body, sim.link_index[b])
    return nearest(sim, other, sim.link_index[a], link, 10.0)


def random_configurations(task, names, count: int, seed: int) -> np.ndarray:
    lower, upper = task.robot.lower_upper(names)
    return lower + np.random.default_rng(seed).random((count, len(names))) * (upper - lower)


def near_contact(checker, Q: np.ndarray, count: int) -> np.ndarray:
    """``count`` configurations on the boundary of the free space: bisection (50 halvings) on the segments from free
    configurations of ``Q`` to colliding ones."""
    free = checker.free_many(Q)
    out = []
    for a, b in zip(Q[free][:count], Q[~free][:count], strict=False):
        for _ in range(50):
            mid = (a + b) / 2
            a, b = (mid, b) if checker.free(mid) else (a, mid)
        out.append(b)
    return np.array(out)


@pytest.mark.integration
@pytest.mark.parametrize("margin_m", [0.0, 0.01])
def test_distances_agree_with_closest_points(task, names, margin_m):
    """Every pair the broad phase keeps has PyBullet's distance (un-inflated robot) to DISTANCE_M, over random
    configurations and configurations on the boundary of contact; a pair it drops is at least its threshold apart; a
    cylinder's bounding capsule is no nearer than the cylinder."""
    environment = [*task.spec.environment, *EXTRA]
    sim = load_pybullet_robot(task.robot.urdf.path)
    bodies = {name: body for body, name in add_environment(sim, environment).items()}
    try:
        with CollisionChecker(
            task.robot, names, {}, environment, task.spec.expected_contacts, margin_m=margin_m
        ) as checker:
            Q = random_configurations(task, names, 2000, 31)
            Q = np.vstack([Q, near_contact(checker, Q, 60)])
            D = checker.distances(Q)
            assert (
                D.shape == (len(Q), len(checker.pairs)) and checker.checks == 2000 + 60 * 50
            )  # distances are not checks
            threshold = np.array([2 * margin_m if b in sim.link_index else margin_m for _, b in checker.pairs])
            compared, penetrating, at_contact = 0, 0, 0
            for q, d in zip(Q, D, strict=True):
                sim.set_positions(names, q)
                for (a, b), mine, limit in zip(checker.pairs, d, threshold, strict=True):
                    theirs = pybullet_distance(sim, bodies, a, b)
                    if not np.isfinite(mine):
                        assert theirs >= limit - DISTANCE_M, (a, b)
                    elif b in ("bowl", "post"):  # its bounding capsule
                        assert mine <= theirs + DISTANCE_M, (a, b)
                    else:
                        assert mine == pytest.approx(theirs, abs=DISTANCE_M), (a, b)
                        compared += 1
                        penetrating += theirs < 0
                        at_contact += abs(theirs - limit) < 1e-6
            assert compared > 5000 and penetrating > 500 and at_contact >= 50
            assert {n for pair in checker.pairs for n in pair} >= {
                "table",
                "panel",
                "bowl",
                "crate",
                "ball",
                "post",
                "head",
                "pelvis",
            }
    finally:
        sim.close()


@pytest.mark.integration
def test_verdicts_equal_free_and_the_pybullet_checker(task, names):
    """free_many is free of each configuration, on random configurations and on the boundary of contact; and the
    reference checker's verdict on the random ones, but for those within DISTANCE_M of a threshold."""
    environment = [*task.spec.environment, *EXTRA]
    args = (task.robot, names, {}, environment, task.spec.expected_contacts)
    with CollisionChecker(*args, margin_m=0.01) as checker, PyBulletChecker(*args, margin_m=0.01) as reference:
        Q = random_configurations(task, names, 3000, 37)
        free = checker.free_many(Q)
        assert free.dtype == bool and free.shape == (len(Q),)
        boundary = near_contact(checker, Q, 100)
        assert np.concatenate([free, checker.free_many(boundary)]).tolist() == [
            checker.free(q) for q in np.vstack([Q, boundary])
        ]
        objects = {o.name for o in environment}
        limits = np.array([0.01 if b in objects else 0.02 for _, b in checker.pairs])
        clear = np.abs(checker.distances(Q) - limits).min(axis=1) > DISTANCE_M
        assert clear.mean() > 0.99 and 0.2 < free.mean() < 0.8
        assert np.array_equal(free[clear], reference.free_many(Q[clear]))
        assert checker.free_many(np.empty((0, len(names)))).shape == (0,)


@pytest.mark.integration
def test_cylinders_are_checked_by_pybullet_where_their_capsule_is_near(task, names, reference):
    """Without allowed contacts, the palms reach the bowl (a cylinder): in every configuration where a bounding capsule
    comes within the margin, the bowl's contacts are PyBullet's closest points on the un-inflated robot, and the verdict
    the reference checker's."""
    sim, objects = reference
    bowl_body = {name: body for body, name in objects.items()}["bowl"]
    args = (task.robot, names, {}, task.spec.environment, ())
    with CollisionChecker(*args, margin_m=0.01) as checker, PyBulletChecker(*args, margin_m=0.01) as pybullet:
        Q = random_configurations(task, names, 3000, 13)
        bowl = [k for k, (_, b) in enumerate(checker.pairs) if b == "bowl"]
        Q = Q[(checker.distances(Q)[:, bowl] < 0.01).any(axis=1)]
        assert len(Q) >= 40
        free = checker.free_many(Q)
        others = np.array([b != "bowl" for _, b in checker.pairs])
        limits = np.array([0.01 if b in objects.values() else 0.02 for _, b in checker.pairs])[others]
        touching = 0
        for q, free_q in zip(Q, free, strict=True):
            mine = {c.a: c.depth_m for c in checker.contacts(q) if c.b == "bowl"}
            sim.set_positions(names, q)
            on_boundary = np.abs(checker.distances(q[None])[0, others] - limits).min() < BOUNDARY_M
            for link in {a for a, b in checker.pairs if b == "bowl"}:
                d = nearest(sim, bowl_body, sim.link_index[link], -1, 10.0)
                on_boundary |= abs(d - 0.01) < BOUNDARY_M
                if abs(d - 0.01) > BOUNDARY_M:
                    assert (link in mine) == (d < 0.01), link
                if link in mine:
                    assert mine[link] == pytest.approx(0.01 - d, abs=DISTANCE_M), link
            touching += bool(mine)
            if not on_boundary:
                assert free_q == pybullet.free(q)
        assert 10 <= touching < len(Q)


@pytest.mark.integration
def test_a_link_without_capsules_is_checked_by_pybullet(task, names, reference, tmp_path):
    """The head as a box: every pair of the head is PyBullet's, in every configuration; the verdicts and contacts are
    the reference checker's."""
    text = (HUMANOID / "humanoid.urdf").read_text()
    head = text.index("<collision>", text.index('<link name="head">'))
    end = text.index("</collision>", head)
    (tmp_path / "humanoid.urdf").write_text(
        text[:head] + '<collision><geometry><box size="0.18 0.2 0.16"/></geometry>' + text[end:]
    )
    (tmp_path / "robot.toml").write_text((HUMANOID / "robot.toml").read_text())
    robot = load_robot(tmp_path)
    args = (robot, names, {}, task.spec.environment, task.spec.expected_contacts)
    with CollisionChecker(*args, margin_m=0.01) as checker, PyBulletChecker(*args, margin_m=0.01) as pybullet:
        assert not any("head" in pair for pair in checker.pairs)
        Q = random_configurations(task, names, 400, 41)
        assert np.array_equal(checker.free_many(Q), pybullet.free_many(Q))
        heads = 0
        for q in Q[:150]:
            mine, theirs = as_found(reference[0], checker.contacts(q)), as_found(reference[0], pybullet.contacts(q))
            assert mine.keys() == theirs.keys()
            assert all(mine[k] == pytest.approx(theirs[k], abs=DISTANCE_M) for k in mine)
            heads += any("head" in k for k in mine)
        assert heads >= 3


@pytest.mark.integration
def test_an_object_on_a_link_no_joint_moves_collides_everywhere(task, names, reference):
    """A block inside the pelvis (which no planned joint moves): every configuration collides, with the block's depth,
    computed once."""
    sim, _ = reference
    block = EnvironmentObject(name="block", shape="box", size_m=(0.1, 0.1, 0.1), pose={"position": (0.05, 0.0, 0.5)})
    with CollisionChecker(
        task.robot, names, {}, [*task.spec.environment, block], task.spec.expected_contacts, margin_m=0.01
    ) as checker:
        assert ("pelvis", "block") not in checker.pairs
        Q = random_configurations(task, names, 50, 43)
        assert not checker.free_many(Q).any()
        depth = {(c.a, c.b): c.depth_m for c in checker.contacts(Q[0])}[("pelvis", "block")]
    bodies = add_environment(sim, [block])
    try:
        assert depth == pytest.approx(
            0.01 - nearest(sim, next(iter(bodies)), sim.link_index["pelvis"], -1, 1.0), abs=DISTANCE_M
        )
    finally:
        pb.removeBody(next(iter(bodies)), physicsClientId=sim.client)


@pytest.mark.integration
def test_pybullet_rounds_box_edges_by_its_margin():
    """PyBullet's box is its half-extents less BOX_ROUNDING_M grown by a ball of that radius: capsules and spheres
    around and into a box, at PyBullet's distances."""
    f = distance_functions()
    client = pb.connect(pb.DIRECT)
    try:
        h = np.array([0.25, 0.5, 0.02])
        box = pb.createMultiBody(
            0,
            pb.createCollisionShape(pb.GEOM_BOX, halfExtents=h.tolist(), physicsClientId=client),
            physicsClientId=client,
        )
        capsule = pb.createMultiBody(
            0,
            pb.createCollisionShape(pb.GEOM_CAPSULE, radius=0.04, height=0.19, physicsClientId=client),
            physicsClientId=client,
        )
        sphere = pb.createMultiBody(
            0, pb.createCollisionShape(pb.GEOM_SPHERE, radius=0.05, physicsClientId=client), physicsClientId=client
        )
        rng = np.random.default_rng(17)
        inner = (np.eye(3), np.zeros(3), h - BOX_ROUNDING_M)
        signs = set()
        for k in range(300):
            position, rotation = rng.uniform(-h - 0.1, h + 0.1), Rotation.random(random_state=k)
            pb.resetBasePositionAndOrientation(
                capsule, position.tolist(), rotation.as_quat().tolist(), physicsClientId=client
            )
            pb.resetBasePositionAndOrientation(sphere, position.tolist(), [0, 0, 0, 1], physicsClientId=client)
            axis = rotation.as_matrix()[:, 2] * 0.095
            mine = float(f["segment_box"](position - axis, position + axis, *inner)) - 0.04 - BOX_ROUNDING_M
            assert mine == pytest.approx(
                min(p[8] for p in pb.getClosestPoints(capsule, box, 10.0, physicsClientId=client)), abs=DISTANCE_M
            )
            mine = float(f["point_box"](position, *inner)) - 0.05 - BOX_ROUNDING_M
            assert mine == pytest.approx(
                min(p[8] for p in pb.getClosestPoints(sphere, box, 10.0, physicsClientId=client)), abs=DISTANCE_M
            )
            signs.add(np.sign(mine))
        assert signs == {-1.0, 1.0}
    finally:
        pb.disconnect(client)


# --- the distances the checker relies on are the real geometry -----------------------------------


def segment_distance(p1, q1, p2, q2) -> float:
    """Distance between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    eps = 1e-15
    if a <= eps and e <= eps:
        return float(np.linalg.norm(r))
    if a <= eps:
        s, t = 0.0, float(np.clip(f / e, 0, 1))
    else:
        c = d1 @ r
        if e <= eps:
            s, t = float(np.clip(-c / a, 0, 1)), 0.0
        else:
            b = d1 @ d2
            denom = a * e - b * b
            s = float(np.clip((b * f - c * e) / denom, 0, 1)) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0:
                s, t = float(np.clip(-c / a, 0, 1)), 0.0
            elif t > 1:
                s, t = float(np.clip((b - c) / a, 0, 1)), 1.0
    return float(np.linalg.norm(p1 + s * d1 - (p2 + t * d2)))


def test_segment_distance_against_brute_force():
    """The analytic helper itself, against a dense grid over both segments' parameters."""
    rng = np.random.default_rng(5)
    grid = np.linspace(0, 1, 401)
    for _ in range(20):
        p1, q1, p2, q2 = rng.normal(size=(4, 3))
        A = p1 + grid[:, None] * (q1 - p1)
        B = p2 + grid[:, None] * (q2 - p2)
        brute = np.linalg.norm(A[:, None] - B[None], axis=-1).min()
        exact = segment_distance(p1, q1, p2, q2)
        assert exact <= brute + 1e-12 and brute - exact <= 0.01
    # parallel and crossing cases by hand
    z = np.zeros(3)
    assert segment_distance(z, np.array([1.0, 0, 0]), np.array([0.5, 1, 0]), np.array([2.0, 1, 0])) == pytest.approx(
        1.0
    )
    assert segment_distance(
        z, np.array([1.0, 0, 0]), np.array([0.5, -1, 0.2]), np.array([0.5, 1, 0.2])
    ) == pytest.approx(0.2)


def capsule_axis(sim, shapes, link):
    """World end points of ``link``'s capsule axis (both at the centre for a sphere) and its radius."""
    origin, tag, attrs = shapes[link]
    T = link_frame(sim, link) @ origin
    half = attrs["length"] / 2 if tag == "capsule" else 0.0
    ends = [(T @ np.array([0.0, 0.0, z, 1.0]))[:3] for z in (-half, half)]
    return ends[0], ends[1], attrs["radius"]


@pytest.mark.integration
def test_closest_points_equal_analytic_capsule_distances(task, names, reference):
    sim, _ = reference
    shapes = urdf_collisions(task)
    assert {tag for _, tag, _ in shapes.values()} == {"capsule", "sphere"}
    pairs = [
        ("left_forearm", "right_forearm"),
        ("left_upper_arm", "right_palm"),
        ("torso", "left_forearm"),
        ("pelvis", "right_forearm"),
        ("head", "left_palm"),
        ("left_palm", "right_palm"),
    ]
    lower, upper = task.robot.lower_upper(names)
    rng = np.random.default_rng(7)
    distances = []
    for _ in range(25):
        sim.set_positions(names, lower + rng.random(len(names)) * (upper - lower))
        for a, b in pairs:
            p1, q1, r1 = capsule_axis(sim, shapes, a)
            p2, q2, r2 = capsule_axis(sim, shapes, b)
            analytic = segment_distance(p1, q1, p2, q2) - r1 - r2
            measured = nearest(sim, sim.body, sim.link_index[a], sim.link_index[b], 10.0)
            assert measured == pytest.approx(analytic, abs=1e-4), (a, b)
            distances.append(analytic)
    assert min(distances) < 0 < max(distances)  # overlapping pairs as well as separate ones


# --- the bowl grasp's scene ----------------------------------------------------------------------


@pytest.mark.integration
def test_start_configuration_is_free(task, names, reference):
    sim, objects = reference
    q = np.array([task.initial_q[n] for n in names])
    with make_checker(task, names, 0.01) as checker:
        assert checker.free(q) and checker.contacts(q) == []
        expected, near = reference_contacts(sim, objects, names, q, 0.01, checker.unchecked_pairs, allowed_pairs(task))
    assert expected == {} and not near


@pytest.mark.integration
def test_left_hand_into_the_table_is_named(task, names, reference):
    """Random configurations until the checker names the left palm or forearm against the
    table; that pair is really closer than the margin, by the reported depth, and the nearest
    point on the table lies on the table's box (0.50 x 1.00 x 0.04 m at (0.55, 0, 0.88))."""
    sim, objects = reference
    margin = 0.01
    table = {name: body for body, name in objects.items()}["table"]
    lower, upper = task.robot.lower_upper(names)
    rng = np.random.default_rng(11)
    with make_checker(task, names, margin) as checker:
        for _ in range(2000):
            q = lower + rng.random(len(names)) * (upper - lower)
            hits = [c for c in checker.contacts(q) if c.b == "table" and c.a in ("left_palm", "left_forearm")]
            if hits:
                break
        else:
            pytest.fail("no configuration puts the left hand into the table")
        assert not checker.free(q)
    sim.set_positions(names, q)
    for hit in hits:
        points = pb.getClosestPoints(sim.body, table, margin, sim.link_index[hit.a], -1, physicsClientId=sim.client)
        assert points
        closest = min(points, key=lambda p: p[8])
        assert closest[8] < margin
        assert hit.depth_m == pytest.approx(margin - closest[8], abs=1e-6)
        on_table = np.abs(np.asarray(closest[6]) - [0.55, 0.0, 0.88])
        assert np.all(on_table <= np.array([0.25, 0.5, 0.02]) + 1e-6)


@pytest.mark.integration
def test_expected_contacts_are_not_checked(task, names, reference):
    """A palm inside the bowl (the grasp's expected contact) is free; the same pose against a
    checker without allowed contacts is not."""
    sim, objects = reference
    bowl = {name: body for body, name in objects.items()}["bowl"]
    lower, upper = task.robot.lower_upper(names)
    rng = np.random.default_rng(13)
    with (
        make_checker(task, names, 0.01) as checker,
        CollisionChecker(task.robot, names, {}, task.spec.environment, (), margin_m=0.01) as strict,
    ):
        found = 0
        for _ in range(3000):
            q = lower + rng.random(len(names)) * (upper - lower)
            sim.set_positions(names, q)
            d = nearest(sim, bowl, sim.link_index["left_palm"], -1, 0.01)
            if d is None or d > 0.01 - BOUNDARY_M:
                continue
            found += 1
            assert ("left_palm", "bowl") in {(c.a, c.b) for c in strict.contacts(q)}
            assert ("left_palm", "bowl") not in {(c.a, c.b) for c in checker.contacts(q)}
        assert found >= 1


# --- inflated_urdf -------------------------------------------------------------------------------


def shapes_of(text: str, element: str) -> list[tuple[str, dict[str, str]]]:
    root = ET.fromstring(text)
    return [(s.tag, dict(s.attrib)) for e in root.iter(element) for s in e.find("geometry")]


@pytest.mark.integration
@pytest.mark.parametrize("margin_m", [0.0, 0.01, 0.035])
def test_inflated_urdf_grows_the_humanoids_collision_shapes(task, margin_m):
    text = task.robot.urdf.path.read_text()
    out = inflated_urdf(text, margin_m)
    before, after = shapes_of(text, "collision"), shapes_of(out, "collision")
    assert len(before) == len(after) == 9
    for (tag, a), (tag2, b) in zip(before, after, strict=True):
        assert tag == tag2
        assert float(b["radius"]) == pytest.approx(float(a["radius"]) + margin_m, abs=1e-12)
        if tag == "capsule":  # the radius already lengthens the capsule at both ends
            assert float(b["length"]) == pytest.approx(float(a["length"]), abs=1e-12)
    assert shapes_of(out, "visual") == shapes_of(text, "visual")  # visuals are untouched


SYNTHETIC = """<robot name="r">
  <link name="a">
    <visual><geometry><box size="0.1 0.2 0.3"/></geometry></visual>
    <collision><geometry><box size="0.1 0.2 0.3"/></geometry></collision>
    <collision><geometry><cylinder radius="0.05" length="0.4"/></geometry></collision>
  </link>
  <link name="b">
    <collision><origin xyz="0 0 0.1"/><geometry><sphere radius="0.02"/></geometry></collision>
    <collision><geometry><capsule radius="0.03" length="0.2"/></geometry></collision>
  </link>
</robot>"""


def test_inflated_urdf_every_primitive_by_hand():
    out = shapes_of(inflated_urdf(SYNTHETIC, 0.01), "collision")
    box, cylinder, sphere, capsule = (b for _, b in out)
    assert np.allclose([float(s) for s in box["size"].split()], [0.12, 0.22, 0.32])
    assert float(cylinder["radius"]) == pytest.approx(0.06) and float(cylinder["length"]) == pytest.approx(0.42)
    assert float(sphere["radius"]) == pytest.approx(0.03)
    assert float(capsule["radius"]) == pytest.approx(0.04) and float(capsule["length"]) == pytest.approx(0.2)
    assert shapes_of(inflated_urdf(SYNTHETIC, 0.01), "visual") == [("box", {"size": "0.1 0.2 0.3"})]
    root = ET.fromstring(inflated_urdf(SYNTHETIC, 0.01))
    assert root.find("link[@name='b']/collision/origin").get("xyz") == "0 0 0.1"


def test_inflated_urdf_refuses_meshes():
    mesh = SYNTHETIC.replace('<sphere radius="0.02"/>', '<mesh filename="m.stl"/>')
    with pytest.raises(StageError, match="mesh"):
        inflated_urdf(mesh, 0.01)


# --- segments ------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", list(range(0, 40)) + [64, 100, 257])
def test_bisection_order_is_a_permutation(n):
    order = bisection_order(n)
    assert sorted(order.tolist()) == list(range(1, max(n, 1)))
    if n >= 2:
        assert order[0] == n // 2  # the middle first


@pytest.mark.integration
def test_segment_configurations_are_spaced_by_the_resolution(task, names):
    resolution = 0.05
    lower, upper = task.robot.lower_upper(names)
    rng = np.random.default_rng(17)
    with make_checker(task, names, 0.01, resolution_rad=resolution) as checker:
        cases = [
            (lower + rng.random(17) * (upper - lower), lower + rng.random(17) * (upper - lower)) for _ in range(10)
        ]
        a = np.zeros(17)
        cases += [(a, a + 0.3), (a, a + 0.049), (a, a.copy()), (a, np.r_[0.2, np.zeros(16)])]
        for a, b in cases:
            Q = checker.segment_configurations(a, b)
            assert Q.ndim == 2 and Q.shape[1] == 17
            span = np.abs(b - a).max()
            if span == 0:
                assert len(Q) == 0
                continue
            j = int(np.argmax(np.abs(b - a)))
            t = (Q[:, j] - a[j]) / (b[j] - a[j])  # interpolation parameter of each
            assert np.allclose(Q, a + t[:, None] * (b - a), atol=1e-12)  # on the straight segment
            assert np.all((t > 1e-12) & (t < 1 - 1e-12))  # end points excluded
            if len(Q):
                assert abs(t[0] - 0.5) <= 0.5 / (len(Q) + 1) + 1e-12  # the middle first
            chain = np.vstack([a, Q[np.argsort(t)], b])
            steps = np.abs(np.diff(chain, axis=0))
            assert steps.max() <= resolution + 1e-12  # every joint, both ends included
            # and no more configurations than needed: one step fewer would be too long
            if len(steps) > 1:
                assert span / (len(steps) - 1) > resolution - 1e-9


@pytest.mark.integration
def test_checks_count_every_configuration(task, names, reference):
    sim, objects = reference
    q0 = np.array([task.initial_q[n] for n in names])
    q1 = q0.copy()
    q1[names.index("left_elbow")] = -0.3
    q1[names.index("right_elbow")] = -0.3
    with make_checker(task, names, 0.01, resolution_rad=0.02) as checker:
        for q in checker.segment_configurations(q0, q1):  # the segment is free, independently
            assert (
                reference_contacts(sim, objects, names, q, 0.01, checker.unchecked_pairs, allowed_pairs(task))[0] == {}
            )
        assert checker.checks == 0
        checker.free(q0)
        checker.free(q1)
        checker.contacts(q0)
        assert checker.checks == 3
        k = len(checker.segment_configurations(q0, q1))
        assert k == 14  # 0.3 rad in steps of at most 0.02 rad: 15 steps, 14 inner points
        assert checker.segment_free(q0, q1)
        assert checker.checks == 3 + k


@pytest.mark.integration
def test_checker_rejects_bad_settings(task, names):
    with pytest.raises(StageError, match="margin"):
        make_checker(task, names, -0.01)
    with pytest.raises(StageError, match="resolution"):
        make_checker(task, names, 0.01, resolution_rad=0.0)
    with pytest.raises(StageError, match="no joint"):
        CollisionChecker(task.robot, ("no_such_joint",), {}, task.spec.environment)


@pytest.mark.integration
@pytest.mark.parametrize(("gap_m", "contact"), [(0.005, False), (-0.001, True)])
def test_a_point_pybullet_reports_across_a_gap_is_not_a_contact(gap_m, contact):
    """Two convex hulls (the shape PyBullet gives a mesh) 5 mm apart: PyBullet still returns a contact point, at a
    positive distance; in_contact, the rule of the checker and of the execution, counts it only when the hulls
    overlap."""
    from dualarm.sim.world import in_contact

    client = pb.connect(pb.DIRECT)
    try:
        cube = [[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)]
        shape = pb.createCollisionShape(pb.GEOM_MESH, vertices=cube, physicsClientId=client)
        a = pb.createMultiBody(1.0, shape, basePosition=[0, 0, 0], physicsClientId=client)
        b = pb.createMultiBody(1.0, shape, basePosition=[0.2 + gap_m, 0, 0], physicsClientId=client)
        pb.performCollisionDetection(physicsClientId=client)
        points = pb.getContactPoints(a, b, physicsClientId=client)
        assert points  # PyBullet reports the pair either way
        assert (min(p[8] for p in points) > 0) is not contact
        assert any(in_contact(p) for p in points) is contact
    finally:
        pb.disconnect(client)
