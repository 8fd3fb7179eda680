"""TV-GDD bounds, eqs (19)-(22), against their closed forms."""

import casadi as cs
import numpy as np
import pytest

from dualarm.ik.velocity.gesture import position_bounds, velocity_bounds


def test_sigmoid_bounds_closed_form():
    """Paper Fig. 2 setting: theta+- = 0, goal = 5; at T_SP the bound is halfway, long after it is the goal."""
    t_sp, c = 9.0, 0.9
    for t in (0.0, 4.5, 9.0, 13.5, 18.0, 60.0):
        lo, hi = position_bounds(t, 0.0, 0.0, 5.0, 5.0, t_sp, c)
        expected = 5.0 / (1.0 + np.exp(-(t - t_sp) / c))
        assert lo == pytest.approx(expected, abs=1e-12) and hi == pytest.approx(expected, abs=1e-12)
    assert position_bounds(t_sp, 0.0, 0.0, 5.0, 5.0, t_sp, c)[0] == pytest.approx(2.5, abs=1e-12)
    assert position_bounds(60.0, 0.0, 0.0, 5.0, 5.0, t_sp, c)[0] == pytest.approx(5.0, abs=1e-12)


def test_smaller_c_switches_faster():
    early = [position_bounds(8.0, 0.0, 0.0, 5.0, 5.0, 9.0, c)[0] for c in (0.1, 0.5, 1.0)]
    assert early[0] < early[1] < early[2]  # before T_SP a sharper sigmoid is still lower


def test_joint_without_goal_keeps_its_limits():
    lo, hi = position_bounds(np.linspace(0, 18, 7), -2.0, 2.0, -2.0, 2.0, 0.75, 1.0)
    np.testing.assert_array_equal(lo, -2.0)
    np.testing.assert_array_equal(hi, 2.0)


def test_velocity_bounds_take_the_tighter_of_eq_21_and_the_limits():
    theta = np.array([0.0, 1.0, -1.9])
    lo, hi = velocity_bounds(theta, np.full(3, -2.0), np.full(3, 2.0), -6.0, 6.0, 2.0)
    np.testing.assert_allclose(lo, [-4.0, -6.0, -0.2])
    np.testing.assert_allclose(hi, [4.0, 2.0, 6.0])


def test_casadi_and_numpy_agree():
    t, theta = cs.SX.sym("t"), cs.SX.sym("theta", 2)
    lo, hi = position_bounds(
        t, np.array([-1.0, -2.0]), np.array([1.0, 2.0]), np.array([0.5, -2.0]), np.array([0.5, 2.0]), 0.75, 1.0
    )
    zlo, zhi = velocity_bounds(theta, lo, hi, -6.0, 6.0, 2.0)
    f = cs.Function("f", [t, theta], [lo, hi, zlo, zhi])
    for tv, th in ((0.0, [0.0, 0.0]), (3.0, [0.7, -1.0])):
        nlo, nhi = position_bounds(
            tv, np.array([-1.0, -2.0]), np.array([1.0, 2.0]), np.array([0.5, -2.0]), np.array([0.5, 2.0]), 0.75, 1.0
        )
        nzlo, nzhi = velocity_bounds(np.array(th), nlo, nhi, -6.0, 6.0, 2.0)
        for a, b in zip(f(tv, th), (nlo, nhi, nzlo, nzhi), strict=True):
            np.testing.assert_allclose(np.asarray(a).ravel(), b, atol=1e-14)
