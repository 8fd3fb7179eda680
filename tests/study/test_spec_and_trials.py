"""The study spec (dualarm.study.spec) and the trials it draws (dualarm.study.trials): bad specs in one line, trials the
same whatever the order they are drawn in, and every trial a valid task whose path is the shape it names (checked from
the Cartesian reference the path stage makes of it, independently of the generator)."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.errors import TaskFileError
from dualarm.run import run_task
from dualarm.study.spec import load_study, study_from_toml
from dualarm.study.trials import trial
from dualarm.tasks.load import task_from_dict

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "studies" / "inconsistency.toml"


def test_the_example_spec_loads():
    spec, base = load_study(EXAMPLE)
    assert spec.trials == 1000 and len(spec.methods) == 7 and base == EXAMPLE.parent


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("trials = 10\n", "spec.toml:name: missing"),
        ('name = "s"\ntrials = 0\n', "trials: 0 is outside the allowed range [1, 1e+06]"),
        ('name = "s"\ntrials = 10\nmethods = ["mc-inverse", "rrt"]\n', "'rrt' is not an IK method"),
        ('name = "s"\ntrials = 10\nmethods = ["mcikrrt"]\n', "'mcikrrt' is not an IK method"),
        ('name = "s"\ntrials = 10\nrepetitions = [9, 3]\n', "repetitions: the low end 9 is above the high end 3"),
        (
            'name = "s"\ntrials = 10\n[shape]\nkinds = ["spiral"]\n',
            "shape.kinds[0]: Input should be 'polygon', 'circle' or 'figure-eight'",
        ),
        ('name = "s"\ntrials = 10\n[shape]\nsize_m = [0.1, 2.0]\n', "2 m is outside the allowed range [0.005, 0.5] m"),
        ('name = "s"\ntrials = 10\n[centre]\nx = [0.4, nan]\n', "centre.x[1]: Input should be a finite number"),
        ('name = "s"\ntrials = 10\ncolour = "red"\n', "colour"),
        ('name = "s"\ntrials = 10\n[inconsistent]\njoint_deviation_rad = 0\n', "inconsistent.joint_deviation_rad"),
        ('name = "s"\ntrials = 10\nhands = ["left", "all"]\n', "hands[1]: Input should be 'left', 'right' or 'both'"),
        ('name = "s"\ntrials = 10\n[carry]\nsize_m = [0.1, 0.2]\n', "carry.size_m"),
        (
            'name = "s"\ntrials = 10\n[carry]\nmaster_to_object = { rpy = [0, 0, 0] }\n',
            "carry.master_to_object.position: missing",
        ),
        ('name = "s"\ntrials = 10.5\n', "trials"),
        ('name = "s"\ntrials = \n', "not valid TOML"),
        ('name = "s"\ntrials = 1\nrobot = "hum\\u0000anoid"\n', "robot: a robot directory or name cannot hold a NUL"),
    ],
)
def test_a_bad_spec_is_one_line_naming_the_key(text, message):
    with pytest.raises(TaskFileError) as info:
        study_from_toml(text, "spec.toml")
    assert message in str(info.value) and "\n" not in str(info.value), str(info.value)


def test_a_missing_spec_file_is_one_line(tmp_path):
    with pytest.raises(TaskFileError, match="no such study spec file"):
        load_study(tmp_path / "nowhere.toml")


def test_trials_are_the_same_whatever_order_they_are_drawn_in():
    """Trial i depends only on (seed, i): drawn forwards, backwards, or alone, the tasks are equal; another seed draws
    others."""
    spec, _ = load_study(EXAMPLE)
    forwards = [trial(spec, i) for i in range(40)]
    backwards = [trial(spec, i) for i in reversed(range(40))][::-1]
    assert all(a.task == b.task and a.features == b.features for a, b in zip(forwards, backwards, strict=True))
    assert trial(spec, 17).task == forwards[17].task
    other = spec.model_copy(update={"seed": 1})
    assert sum(trial(other, i).task == forwards[i].task for i in range(40)) == 0
    kinds = {t.features["kind"] for t in forwards}
    assert kinds == {"polygon", "circle", "figure-eight"} and {t.features["hand"] for t in forwards} == {
        "left",
        "right",
        "both",
    }
    for t in forwards:
        f = t.features
        assert (
            spec.repetitions[0] <= f["repetitions"] <= spec.repetitions[1]
            and (f["vertices"] == 0) == (f["kind"] != "polygon")
            and 0.05 <= f["size_m"] <= 0.15
        )


def _circle_fit(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """The circle through planar points (M, 2) by least squares on |x - c|^2 = r^2: its centre, radius and largest
    miss."""
    A = np.column_stack([2 * points, np.ones(len(points))])
    solution = np.linalg.lstsq(A, (points**2).sum(axis=1), rcond=None)[0]
    centre = solution[:2]
    radius = float(np.sqrt(solution[2] + centre @ centre))
    return centre, radius, float(np.abs(np.linalg.norm(points - centre, axis=1) - radius).max())


def _matrix(rotation, position) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation, position
    return T


@pytest.mark.parametrize("index", range(12))
def test_each_trial_is_a_valid_task_drawing_its_shape(index):
    """The path stage's reference of one repetition (the hand's positions, robot base frame), split by the task's moves:
    closed, in one plane (1e-9 m) whose normal is within tilt_rad of x; a circle's samples on one circle; a polygon's
    edges straight and its vertices on one circle; a figure-eight's two loops circles of equal radius touching at its
    start, crossed without turning back. In a carry (``both``), the left hand draws and the right hand's every pose is
    the left's times the spec's master_to_object and inverse(slave_to_object) (eq 11, composed here with scipy)."""
    spec, base = load_study(EXAMPLE)
    t = trial(spec, index)
    f = t.features
    assert task_from_dict(t.task, base_dir=base).spec.repetitions == f["repetitions"]
    task = task_from_dict({**t.task, "repetitions": 1}, base_dir=base)
    reference = run_task(task, None, stages=("path",)).reference
    drawing = "left" if f["hand"] == "both" else f["hand"]
    assert set(reference.hands) == ({"left", "right"} if f["hand"] == "both" else {drawing})
    if f["hand"] == "both":
        carry = spec.carry
        master, slave = (
            _matrix(Rotation.from_euler("xyz", grip.rpy).as_matrix(), grip.position)
            for grip in (carry.master_to_object, carry.slave_to_object)
        )
        left, right = reference.hands["left"], reference.hands["right"]
        for k in range(len(reference.t)):
            assert np.allclose(
                _matrix(left.rotation[k], left.position[k]) @ master @ np.linalg.inv(slave),
                _matrix(right.rotation[k], right.position[k]),
                atol=1e-12,
            )
        assert np.allclose(
            np.linalg.norm(left.position - right.position, axis=1), 0.24, atol=1e-12
        )  # the palms hold the box's 0.24 m
    p = reference.hands[drawing].position
    assert np.linalg.norm(p[0] - p[-1]) < 1e-9
    centred = p - p.mean(axis=0)
    _, _, (a, b, normal) = np.linalg.svd(centred)
    assert np.abs(centred @ normal).max() < 1e-9
    assert np.arccos(abs(normal[0])) <= spec.shape.tilt_rad + 1e-9
    planar = np.column_stack([centred @ a, centred @ b])
    ends = np.searchsorted(reference.t, np.cumsum([0.0] + [move["duration_s"] for move in t.task["moves"]]) - 1e-9)
    moves = [planar[start : end + 1] for start, end in zip(ends[:-1], ends[1:], strict=True)]
    if f["kind"] == "circle":
        assert _circle_fit(planar)[2] < 1e-9
    elif f["kind"] == "polygon":
        assert len(moves) == f["vertices"]
        for edge in moves:
            direction = (edge[-1] - edge[0]) / np.linalg.norm(edge[-1] - edge[0])
            assert np.abs((edge - edge[0]) @ np.array([-direction[1], direction[0]])).max() < 1e-9  # straight
        assert _circle_fit(np.array([edge[0] for edge in moves]))[2] < 1e-9
    else:
        (c1, r1, miss1), (c2, r2, miss2) = (_circle_fit(loop) for loop in moves)
        assert max(miss1, miss2) < 1e-9 and r1 == pytest.approx(r2, rel=1e-9)
        assert np.linalg.norm(c1 - c2) == pytest.approx(2 * r1, rel=1e-9)  # two loops touching at the start
        assert np.linalg.norm(planar[0] - (c1 + c2) / 2) < 1e-9
        out, back = moves[0][-1] - moves[0][-2], moves[1][1] - moves[1][0]
        assert (
            out @ back / np.linalg.norm(out) / np.linalg.norm(back) > 0.999
        )  # through the centre without turning back: an eight
