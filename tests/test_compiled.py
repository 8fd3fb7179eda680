"""CasADi Functions compiled to machine code: the same results as CasADi's virtual machine, kept on disk, and the
Function itself where there is no compiler."""

import subprocess

import casadi as cs
import numpy as np
import pytest

from dualarm.arrays import RIGID_TOLERANCE
from dualarm.errors import InvalidArgumentError
from dualarm.ik.analytic.mc_inverse import McInverse
from dualarm.model.kinematics import ChainKinematics
from dualarm.numerics import compiled as compiled_module
from dualarm.numerics.compiled import compiled


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DUALARM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("DUALARM_COMPILE", raising=False)
    return tmp_path / "cache"


def test_the_compiled_mc_inverse_equals_the_virtual_machine_bit_for_bit(humanoid, cache, monkeypatch):
    """On reachable poses, singular ones (straight elbow), poses out of reach and random arm angles: every candidate and
    every reason."""
    chain = humanoid.hand_chain("left")
    solver = McInverse.of(chain)
    monkeypatch.setenv("DUALARM_COMPILE", "0")
    plain = McInverse._derive(chain, (0.0, 0.0, 1.0)).candidates
    monkeypatch.delenv("DUALARM_COMPILE")
    assert solver.candidates.class_name() == "External" and plain.class_name() == "SXFunction"
    rng = np.random.default_rng(7)
    Q = rng.uniform(solver.lower, solver.upper, (400, 7))
    Q[:50, 3] = 0.0  # straight elbows
    T = ChainKinematics.of(chain).poses(Q)
    T[50:100, :3, 3] *= 3.0  # out of reach
    psi = rng.uniform(-np.pi, np.pi, len(T))
    machine = [np.asarray(x) for x in plain.map(len(T))(np.hstack(list(T)), psi[None])]
    native = [np.asarray(x) for x in compiled(plain).map(len(T))(np.hstack(list(T)), psi[None])]
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(machine, native, strict=True))
    assert len(list(cache.glob("mc_inverse-*.so"))) == 1


def test_a_compiled_function_is_loaded_from_the_cache_without_compiling(cache, monkeypatch):
    x = cs.SX.sym("x", 3)
    f = cs.Function("cached_test", [x], [cs.sin(x) * cs.atan2(x[0], x[1])])
    first = compiled(f)
    assert first.class_name() == "External"

    def refuse(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(subprocess, "run", refuse)
    again = compiled(f)
    assert again.class_name() == "External"
    np.testing.assert_array_equal(np.asarray(again([0.3, -1.2, 2.0])), np.asarray(f([0.3, -1.2, 2.0])))


@pytest.mark.parametrize("environment", [{"DUALARM_COMPILE": "0"}, {"CC": "/nonexistent/cc"}])
def test_without_a_compiler_the_function_is_used_as_it_is(cache, monkeypatch, environment):
    for key, value in environment.items():
        monkeypatch.setenv(key, value)
    x = cs.SX.sym("x")
    f = cs.Function("uncompiled_test", [x], [2 * x])
    assert compiled(f) is f
    assert not cache.exists()


def test_a_compiler_that_fails_leaves_the_function_as_it_is(cache, tmp_path, monkeypatch):
    failing = tmp_path / "cc"
    failing.write_text("#!/bin/sh\necho 'cc: no' >&2\nexit 1\n")
    failing.chmod(0o755)
    monkeypatch.setenv("CC", str(failing))
    x = cs.SX.sym("x")
    f = cs.Function("failing_test", [x], [2 * x])
    assert compiled(f) is f
    assert not list(cache.glob("*.so"))
    assert compiled_module.FLAGS[:2] == ("-O2", "-ffp-contract=off")  # no FMA: the virtual machine's rounding


def test_one_pose_calls_equal_the_batched_path_and_check_their_inputs(humanoid):
    """McInverse.solve checks its inputs inside the compiled call; what it does not accept is named as the numpy checks
    name it."""
    solver = McInverse.of(humanoid.hand_chain("right"))
    rng = np.random.default_rng(3)
    Q = rng.uniform(solver.lower, solver.upper, (200, 7))
    T, psi = ChainKinematics.of(solver.chain).poses(Q), rng.uniform(-np.pi, np.pi, 200)
    q, reason = solver.solve_many(T, psi)
    for i in range(len(T)):
        one = solver.solve(T[i], psi[i])
        assert np.array_equal(one.q, q[i]) and np.array_equal(one.reason, reason[i])
    assert np.array_equal(
        solver.solve(T[0].tolist(), np.float32(psi[0])).q, solver.solve(T[0], float(np.float32(psi[0]))).q
    )  # lists and numpy scalars too
    reflected, tilted, skewed = T[0].copy(), T[0].copy(), T[0].copy()
    reflected[:3, 0] *= -1
    tilted[3, 0] = 10 * RIGID_TOLERANCE
    skewed[0, 1] += 10 * RIGID_TOLERANCE
    for pose, angle, message in [
        (np.where(np.eye(4, dtype=bool), np.nan, T[0]), 0.0, r"^pose: is not finite at index \(0, 0\)"),
        (np.where(np.eye(4, dtype=bool), np.inf, T[0]), 0.0, r"^pose: is not finite"),
        (reflected, 0.0, "^pose: is not a rigid transform"),
        (tilted, 0.0, "^pose: is not a rigid transform"),
        (skewed, 0.0, "^pose: is not a rigid transform"),
        (T[0], float("nan"), "^psi: is not finite"),
        (T[0], -np.inf, "^psi: is not finite"),
        (T[0][:3], 0.0, r"^pose: expected shape \(4, 4\)"),
        (T[0], [0.1, 0.2], r"^psi: expected shape \(\)"),
    ]:
        with pytest.raises(InvalidArgumentError, match=message):
            solver.solve(pose, angle)
