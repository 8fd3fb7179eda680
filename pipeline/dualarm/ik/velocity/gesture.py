"""TV-GDD time-varying gesture bounds (Zhang, Kong, Niu, section 3.1).

Eq (19) moves each joint's position bounds from the physical limits theta+- toward the goals
theta_goal+- along a sigmoid centred at T_SP with time constant c_tuning; eq (21) turns position
bounds into velocity bounds with the scaling nu, and eq (22) intersects them with the velocity
limits. The functions work on numpy arrays and CasADi expressions alike.
"""

from __future__ import annotations

import casadi as cs
import numpy as np


def _lib(*values):
    return cs if any(isinstance(v, (cs.SX, cs.MX)) for v in values) else np


def position_bounds(t, lower, upper, goal_lower, goal_upper, t_sp: float, c_tuning: float):
    """theta_new-(t), theta_new+(t) of eq (19) [rad].

    Args:
        t: time [s].
        lower, upper: physical limits theta-, theta+ [rad].
        goal_lower, goal_upper: goals theta_goal-, theta_goal+ [rad] (equal to the limits for a
            joint without a goal).
        t_sp: T_SP = T_d / N [s].
        c_tuning: time-tuning parameter, 0 < c <= 1 [s].
    """
    lib = _lib(t)
    sigmoid = 1.0 / (1.0 + lib.exp(-(t - t_sp) / c_tuning))  # eq (19)
    return lower + (goal_lower - lower) * sigmoid, upper + (goal_upper - upper) * sigmoid


def velocity_bounds(theta, lower_t, upper_t, qd_min, qd_max, nu: float, lower_rate=0.0, upper_rate=0.0):
    """zeta_new-(t), zeta_new+(t) of eqs (21)-(22) [rad/s].

    Args:
        theta: joint positions [rad].
        lower_t, upper_t: theta_new-(t), theta_new+(t) [rad].
        qd_min, qd_max: joint velocity limits [rad/s].
        nu: scaling nu > 0 of eq (21) [1/s].
        lower_rate, upper_rate: the bounds' own rates [rad/s], added to eq (21) as a feedforward
            (not in the paper, which uses 0): without it a joint pressed against a closing bound
            lags it by about rate / nu.
    """
    lib = _lib(theta, lower_t)
    lower = nu * (lower_t - theta) + lower_rate  # eq (21)
    upper = nu * (upper_t - theta) + upper_rate
    return lib.fmax(qd_min, lower), lib.fmin(qd_max, upper)  # eq (22)
