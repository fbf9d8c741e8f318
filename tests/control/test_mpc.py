"""The hybrid MPC (pwa_pipeline.control.mpc): its MILP optimum is the best over every mode
sequence, its big-M constants are the exact box bounds, its closed loop tracks a reachable
reference on the paper's system, and an infeasible problem says why."""

import itertools
import re
import time

import numpy as np
import pytest
import scipy.optimize
from scipy.optimize import linprog

from pwa_pipeline.control import HybridMPC, PWAStateSpace
from pwa_pipeline.control.mpc import formulation
from pwa_pipeline.control.mpc.controller import DEFAULT_TIME_LIMIT, MAX_HORIZON
from pwa_pipeline.control.mpc.formulation import STATE_MARGIN, affine_range


def _siso(theta, regions, y_range=(-2.0, 2.0), u_range=(-1.0, 1.0)) -> PWAStateSpace:
    """A 1-input 1-output PWA model with state x = [y(k−1), u(k−1)]: mode i predicts
    y = θ_i · [y(k−1), u(k−1), 1] where z = [y(k−1), u(k−1), u(k)] is in its region."""
    theta = np.asarray(theta, float)
    s = len(theta)
    A = np.zeros((s, 2, 2))
    A[:, 0, :] = theta[:, :2]
    B = np.zeros((s, 2, 1))
    B[:, 1, 0] = 1.0
    f = np.zeros((s, 2))
    f[:, 0] = theta[:, 2]
    lower = np.array([y_range[0], u_range[0], u_range[0]])
    upper = np.array([y_range[1], u_range[1], u_range[1]])
    return PWAStateSpace(A, B, f, theta[:, None, :2], theta[:, 2:3], regions, lower, upper,
                         output_lags=1, input_lags=1)


#: Two modes split by y(k−1) + 0.5·u(k) ≶ 0.2 (the current input takes part in the switch),
#: discontinuous across the boundary, one of them expanding.
TINY_THETA = [[0.6, 0.8, 0.3], [1.1, -0.5, -0.2]]
TINY_REGIONS = [(np.array([[1.0, 0.0, 0.5]]), np.array([0.2])),
                (np.array([[-1.0, 0.0, -0.5]]), np.array([-0.2]))]


@pytest.fixture(scope="module")
def tiny():
    return _siso(TINY_THETA, TINY_REGIONS)


def _brute_force(ss: PWAStateSpace, N: int, x0, ref, Q, R, u_min, u_max, delta: bool):
    """The optimum over every mode sequence (i_0 … i_N), each a linear program with that
    sequence fixed: the same cost and conventions as HybridMPC (outputs y_1 … y_N, the mode of
    step N with u_{N−1} held, the computed state entries STATE_MARGIN inside the envelope),
    written out independently of its code. Returns (cost, inputs) of the best sequence."""
    n, r, m = ss.n_states, ss.n_inputs, ss.n_outputs
    lower, upper = ss.envelope
    margin = STATE_MARGIN * (upper[:n] - lower[:n]) / 2
    margin[ss.n_outputs * ss.output_lags:] = 0.0  # the input lags copy u, bounded by u_min/max
    if ss.output_lags > 1:
        raise NotImplementedError("older output lags are copies too")
    u_prev = x0[n - r * ss.input_lags::ss.input_lags] if delta else np.zeros(r)
    # variables: u_0..u_{N−1} (N r), x_1..x_N (N n), y_1..y_N (N m), t_y (N m), t_u (N r)
    nu, nx, ny = N * r, N * n, N * m
    size = nu + nx + 2 * ny + nu

    def U(k):
        return np.arange(r) + k * r

    def X(k):  # k ≥ 1
        return nu + (k - 1) * n + np.arange(n)

    def Y(k):  # k ≥ 1
        return nu + nx + (k - 1) * m + np.arange(m)

    def TY(k):
        return nu + nx + ny + (k - 1) * m + np.arange(m)

    def TU(k):
        return nu + nx + 2 * ny + k * r + np.arange(r)

    c = np.zeros(size)
    for k in range(1, N + 1):
        c[TY(k)] = Q
    for k in range(N):
        c[TU(k)] = R
    bounds = ([(lo, hi) for lo, hi in zip(u_min, u_max, strict=True)] * N
              + [(lo, hi) for lo, hi in zip(lower[:n] + margin, upper[:n] - margin,
                                            strict=True)] * N
              + [(None, None)] * ny + [(0, None)] * (ny + nu))
    best = (np.inf, None)
    for seq in itertools.product(range(ss.n_modes), repeat=N + 1):
        A_eq, b_eq, A_ub, b_ub = [], [], [], []

        def row():
            return np.zeros(size)

        for k in range(N + 1):
            i = seq[k]
            ku = min(k, N - 1)
            H, h = ss.regions[i]
            for j in range(len(h)):  # z_k in P_i
                a, b = row(), h[j]
                a[U(ku)] += H[j, n:]
                if k == 0:
                    b -= H[j, :n] @ x0
                else:
                    a[X(k)] += H[j, :n]
                A_ub.append(a)
                b_ub.append(b)
            if k < N:  # x_{k+1} = A_i x_k + B_i u_k + f_i
                for t in range(n):
                    a, b = row(), ss.f[i, t]
                    a[X(k + 1)[t]] = 1.0
                    a[U(k)] -= ss.B[i, t]
                    if k == 0:
                        b += ss.A[i, t] @ x0
                    else:
                        a[X(k)] -= ss.A[i, t]
                    A_eq.append(a)
                    b_eq.append(b)
            if k >= 1:  # y_k = C_i x_k + g_i, t_y ≥ |y_k − r_k|
                for p in range(m):
                    a = row()
                    a[Y(k)[p]] = 1.0
                    a[X(k)] -= ss.C[i, p]
                    A_eq.append(a)
                    b_eq.append(ss.g[i, p])
                    for sign in (1.0, -1.0):
                        a = row()
                        a[Y(k)[p]], a[TY(k)[p]] = sign, -1.0
                        A_ub.append(a)
                        b_ub.append(sign * ref[k - 1, p])
        for k in range(N):  # t_u ≥ |u_k − u_{k−1}| (or |u_k|)
            for q in range(r):
                for sign in (1.0, -1.0):
                    a, b = row(), 0.0
                    a[U(k)[q]], a[TU(k)[q]] = sign, -1.0
                    if delta and k >= 1:
                        a[U(k - 1)[q]] = -sign
                    elif delta:
                        b = sign * u_prev[q]
                    A_ub.append(a)
                    b_ub.append(b)
        res = linprog(c, A_ub=np.array(A_ub), b_ub=b_ub, A_eq=np.array(A_eq), b_eq=b_eq,
                      bounds=bounds, method="highs")
        if res.status == 0 and res.fun < best[0]:
            best = (res.fun, res.x[:nu].reshape(N, r))
    return best


def _check_plan(ss: PWAStateSpace, mpc: HybridMPC, plan, x0) -> None:
    """The plan obeys the model in its own modes: dynamics, outputs, regions, bounds."""
    N = mpc.horizon
    np.testing.assert_array_equal(plan.x[0], x0)
    lower, upper = ss.envelope
    n = ss.n_states
    for k in range(N + 1):
        i = plan.modes[k]
        u = plan.u[min(k, N - 1)]
        z = np.concatenate([plan.x[k], u])
        H, h = ss.regions[i]
        assert np.all(H @ z <= h + 1e-6), (k, i)
        if k < N:
            np.testing.assert_allclose(plan.x[k + 1], ss.A[i] @ plan.x[k] + ss.B[i] @ u + ss.f[i],
                                       atol=1e-6)
        if k >= 1:
            np.testing.assert_allclose(plan.y[k - 1], ss.C[i] @ plan.x[k] + ss.g[i], atol=1e-6)
    assert np.all(plan.u >= mpc.u_min - 1e-9) and np.all(plan.u <= mpc.u_max + 1e-9)
    assert np.all(plan.x[1:] >= lower[:n] - 1e-9) and np.all(plan.x[1:] <= upper[:n] + 1e-9)


# --- exactness ----------------------------------------------------------------------------

@pytest.mark.parametrize("penalty", ["delta", "level"])
def test_milp_optimum_is_the_best_mode_sequence(tiny, penalty):
    """On 6 random (x0, reference) pairs the MILP's optimum equals the best of the 2^4 linear
    programs with the mode sequence fixed, and its plan obeys the model in its modes."""
    N = 3
    mpc = HybridMPC(tiny, N, Q=1.0, R=0.05, u_min=-0.8, u_max=0.9, input_penalty=penalty)
    rng = np.random.default_rng(3)
    switched = 0
    for _ in range(6):
        x0 = np.array([rng.uniform(-1.0, 1.0), rng.uniform(-0.8, 0.9)])
        ref = rng.uniform(-1.8, 1.8, size=(N, 1))
        plan = mpc.solve(x0, ref)
        cost, u = _brute_force(tiny, N, x0, ref, mpc.Q, mpc.R, mpc.u_min, mpc.u_max,
                               penalty == "delta")
        assert plan.optimal and plan.status == 0
        assert plan.cost == pytest.approx(cost, abs=1e-6, rel=1e-6)
        _check_plan(tiny, mpc, plan, x0)
        switched += len(set(plan.modes.tolist())) > 1
    assert switched >= 2  # the optima go through both modes, so the binaries matter


def test_big_m_constants_are_the_box_bounds(tiny, default_30db):
    """Each big-M is max (or min) of its affine function over the box of z, checked against
    a linear program over that box: a constant too small (e.g. halved) cuts off feasible
    points, one too large only weakens the relaxation; both differ from these values."""
    for ss, kwargs in ((tiny, {"u_min": -0.8, "u_max": 0.9}),
                       (default_30db.to_state_space(), {})):
        mpc = HybridMPC(ss, 2, **kwargs)
        lower, upper = mpc.program.box
        box = list(zip(lower, upper, strict=True))
        np.testing.assert_array_equal(lower[ss.n_states:], mpc.u_min)
        np.testing.assert_array_equal(upper[:ss.n_states], ss.envelope[1][:ss.n_states])

        def lp_max(a, b):
            return -linprog(-a, bounds=box, method="highs").fun + b

        for (H, h), M in zip(ss.regions, mpc.program.region_big_m, strict=True):
            expected = [lp_max(H[j], -h[j]) for j in range(len(h))]
            np.testing.assert_allclose(M, expected, rtol=1e-9, atol=1e-9)
        low, high = mpc.program.expression_bounds
        p = ss.n_states + ss.n_inputs
        assert len(mpc.program.expressions) > 0
        for e, expr in enumerate(mpc.program.expressions):
            for i in range(ss.n_modes):
                a, b = expr[i, :p], expr[i, p]
                np.testing.assert_allclose(high[e, i], lp_max(a, b), rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(low[e, i], -lp_max(-a, -b), rtol=1e-9, atol=1e-9)
        # every mode-dependent row of the dynamics and outputs is one of the expressions
        E = np.concatenate([np.concatenate([ss.A, ss.B, ss.f[:, :, None]], axis=2),
                            np.concatenate([ss.C, np.zeros((ss.n_modes, ss.n_outputs,
                                                            ss.n_inputs)),
                                            ss.g[:, :, None]], axis=2)], axis=1)
        for t in range(E.shape[1]):
            if not np.all(E[:, t] == E[0, t]):
                assert any(np.array_equal(E[:, t], expr) for expr in mpc.program.expressions)


def test_affine_range_is_the_extreme_over_the_corners():
    rng = np.random.default_rng(0)
    G, q = rng.normal(size=(5, 3)), rng.normal(size=5)
    lower, upper = -rng.uniform(0.5, 2, 3), rng.uniform(0.5, 2, 3)
    corners = np.array(list(itertools.product(*zip(lower, upper, strict=True))))
    values = corners @ G.T + q
    low, high = affine_range(G, q, lower, upper)
    np.testing.assert_allclose(low, values.min(axis=0))
    np.testing.assert_allclose(high, values.max(axis=0))


# --- tracking on the paper's system --------------------------------------------------------

def _equilibrium_input(ss: PWAStateSpace, y: np.ndarray) -> tuple[int, np.ndarray]:
    """The mode holding the state of a constant output y and the input that holds y there:
    y = C_y y + C_u u + g with x = [y; u] (na = nb = 1) solved for u."""
    m = ss.n_outputs
    for i in range(ss.n_modes):
        Cy, Cu = ss.C[i][:, :m], ss.C[i][:, m:]
        u = np.linalg.solve(Cu, y - Cy @ y - ss.g[i])
        if ss.mode_of(np.concatenate([y, u]), u) == i:
            return i, u
    raise AssertionError("no mode holds the equilibrium")


def test_closed_loop_tracks_a_reachable_reference(default_30db, sim_30db, tmp_path):
    """From a measured state in one quadrant to a constant reference in another: the model's
    own closed loop reaches it and stays.

    The reference (−1, −0.5) is an equilibrium of the identified model inside a region
    (checked below) with its input inside the bounds, so the 1-norm cost with the move
    penalty is zero there and the optimal plan holds it exactly; what remains is the solver's
    tolerance (relative MIP gap 1e-6 on a cost that tends to 0, primal feasibility 1e-7), so
    the last 5 of 25 samples must be within 1e-5 of it."""
    ss = PWAStateSpace.from_json(default_30db.to_state_space().to_json(tmp_path / "ss.json"))
    y_ref = np.array([-1.0, -0.5])
    mode, u_eq = _equilibrium_input(ss, y_ref)
    mpc = HybridMPC(ss, horizon=6)
    assert np.all(u_eq > mpc.u_min) and np.all(u_eq < mpc.u_max)
    x0 = ss.states(sim_30db.u_train[0], sim_30db.y_train[0])[0]
    assert ss.mode_of(x0, sim_30db.u_train[0][1]) != mode  # the loop has to switch modes
    run = mpc.closed_loop(x0, y_ref, steps=25)
    assert run.y.shape == (25, 2) and run.u.shape == (25, 2) and run.x.shape == (26, 4)
    np.testing.assert_allclose(run.y[-5:], np.tile(y_ref, (5, 1)), atol=1e-5)
    np.testing.assert_allclose(run.u[-1], u_eq, atol=1e-4)
    assert run.modes[-1] == mode and len(set(run.modes.tolist())) > 1
    assert np.all(run.u >= mpc.u_min - 1e-9) and np.all(run.u <= mpc.u_max + 1e-9)
    assert np.all(ss.in_envelope(run.x[:-1], run.u))
    # the states are the model's: each one is the step of the one before
    x_next, y = ss.step(run.x[:-1], run.u)
    np.testing.assert_allclose(x_next, run.x[1:])
    np.testing.assert_allclose(y, run.y)


# --- bad input ----------------------------------------------------------------------------

def test_infeasible_input_bounds_name_the_bound(default_30db, sim_30db):
    """Inputs pinned at the top of their range drive y1 towards 6.5, above the envelope's
    3.7: infeasible over 10 steps, and the message says the input bound is the cause."""
    ss = default_30db.to_state_space()
    top = ss.envelope[1][ss.n_states:]
    mpc = HybridMPC(ss, 10, u_min=top, u_max=top)
    x0 = ss.states(sim_30db.u_train[0], sim_30db.y_train[0])[0]
    with pytest.raises(ValueError, match=r"infeasible \(HiGHS status 2.*input bounds.*u_min"):
        mpc.solve(x0, [1.0, 1.0])


def test_infeasible_horizon_names_the_envelope():
    """y = 2·y(k−1) + 0.1·u(k−1) from y(−1) = 0.3 leaves [−1, 1] at the second predicted
    step whatever the input: a horizon of 4 is infeasible, 1 is not."""
    ss = _siso([[2.0, 0.1, 0.0]], [(np.zeros((0, 3)), np.zeros(0))], y_range=(-1.0, 1.0))
    x0 = np.array([0.3, 0.0])
    HybridMPC(ss, 1).solve(x0, [0.0])
    with pytest.raises(ValueError, match=r"infeasible.*data envelope for the horizon of 4.*"
                                         r"at most 1 step"):
        HybridMPC(ss, 4).solve(x0, [0.0])
    with pytest.raises(ValueError, match="at sample 0: the MPC problem is infeasible"):
        HybridMPC(ss, 4).closed_loop(x0, [0.0], steps=3)


def test_an_unreachable_reference_is_named_not_blamed_on_the_horizon(tiny):
    """Chasing y_ref = 100 (the model's outputs over the envelope lie in [−2.9, 2.5]) drives
    the state to the envelope's edge until no input keeps it inside: the message names the
    reference as out of reach, with the range, instead of telling to shorten a horizon of 1
    or to start farther inside; an infeasible state with a reference in range is blamed on
    the envelope whatever the reference."""
    mpc = HybridMPC(tiny, 1)
    np.testing.assert_allclose(mpc.output_range(), ([-2.9], [2.5]))
    with pytest.raises(ValueError) as info:
        mpc.closed_loop([0.0, 0.0], [100.0], steps=20)
    message = str(info.value)
    assert re.search(r"^at sample \d+: the MPC problem is infeasible .*: the reference is out "
                     r"of the model's reach: y_ref = 100 for output y1 \(step 1\) is outside "
                     r"\[-2\.9, 2\.5\], the range of its outputs over the data envelope", message)
    assert "Set a reference inside that range" in message and "horizon" not in message
    np.testing.assert_allclose(mpc.closed_loop([0.0, 0.0], [0.9], steps=20).y[-1], [0.9])
    ss = _siso([[2.0, 0.1, 0.0]], [(np.zeros((0, 3)), np.zeros(0))], y_range=(-1.0, 1.0))
    with pytest.raises(ValueError, match=r"whatever the input .* and whatever the reference"):
        HybridMPC(ss, 4).solve([0.3, 0.0], [0.5])


def test_bad_arguments_are_named(tiny):
    with pytest.raises(ValueError, match="horizon must be"):
        HybridMPC(tiny, 0)
    with pytest.raises(ValueError, match=r"u_max\[0\] = 3 is outside the data envelope"):
        HybridMPC(tiny, 2, u_max=3.0)
    with pytest.raises(ValueError, match=r"u_min\[0\] = 0.5 is above u_max\[0\] = 0.2"):
        HybridMPC(tiny, 2, u_min=0.5, u_max=0.2)
    with pytest.raises(ValueError, match="Q must hold finite weights >= 0"):
        HybridMPC(tiny, 2, Q=-1.0)
    with pytest.raises(ValueError, match="input_penalty"):
        HybridMPC(tiny, 2, input_penalty="quadratic")
    mpc = HybridMPC(tiny, 2)
    with pytest.raises(ValueError, match=r"x is outside the data envelope: y1\(k-1\) = 5"):
        mpc.solve([5.0, 0.0], [0.0])
    with pytest.raises(ValueError, match=r"y_ref must have shape \(1,\).*or \(2, 1\)"):
        mpc.solve([0.0, 0.0], [[0.0], [0.0], [0.0]])
    assert tiny.state_names[1] == "u1(k-1)"
    np.testing.assert_array_equal(mpc.previous_input([0.1, -0.4]), [-0.4])


# --- bounded cost -------------------------------------------------------------------------

def test_a_horizon_above_the_limit_is_refused_at_once(tiny):
    """``HybridMPC(horizon=10**6)`` built a program of millions of rows without end; the
    limit is checked before anything is built, and the largest horizon allowed builds."""
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=rf"horizon = 1000000 is above the limit of "
                                         rf"{MAX_HORIZON} samples: .* binaries"):
        HybridMPC(tiny, 10**6)
    assert time.perf_counter() - t0 < 1.0
    with pytest.raises(ValueError, match="above the limit"):
        HybridMPC(tiny, MAX_HORIZON + 1)
    assert HybridMPC(tiny, MAX_HORIZON).horizon == MAX_HORIZON


def _stopped_by_the_clock(monkeypatch, with_plan: bool) -> list[dict]:
    """Make HiGHS report its time limit reached, when it has one (with the plan it solved,
    or none), and record the options it was given."""
    options = []

    def milp(*args, **kwargs):
        options.append(kwargs["options"])
        res = scipy.optimize.milp(*args, **kwargs)
        if "time_limit" not in kwargs["options"]:
            return res
        res.status = 1
        res.message = "Time limit reached. (HiGHS Status 13: Time limit reached)"
        if not with_plan:
            res.x = None
        return res

    monkeypatch.setattr(formulation, "milp", milp)
    return options


def test_every_solve_has_a_time_limit_by_default(tiny, monkeypatch):
    """An 8-mode MPC at horizon 10 took 73 s CPU with no limit: HiGHS now gets
    `DEFAULT_TIME_LIMIT` seconds per solve unless told otherwise."""
    options = _stopped_by_the_clock(monkeypatch, with_plan=True)
    mpc = HybridMPC(tiny, 3)
    assert mpc.time_limit == DEFAULT_TIME_LIMIT
    mpc.solve([0.0, 0.0], [0.5])
    assert options[-1]["time_limit"] == DEFAULT_TIME_LIMIT
    HybridMPC(tiny, 3, time_limit=2.5).solve([0.0, 0.0], [0.5])
    assert options[-1]["time_limit"] == 2.5
    HybridMPC(tiny, 3, time_limit=None).solve([0.0, 0.0], [0.5])
    assert "time_limit" not in options[-1]


def test_the_time_limit_reached_is_said_in_one_line_of_our_own(tiny, monkeypatch):
    """With a plan: returned, not optimal, its message one line saying the limit was hit;
    without: a RuntimeError in one line naming the limit and what to change. Never HiGHS's
    own text."""
    _stopped_by_the_clock(monkeypatch, with_plan=True)
    plan = HybridMPC(tiny, 3, time_limit=0.5).solve([0.0, 0.0], [0.5])
    assert plan.status == 1 and not plan.optimal
    assert plan.message.startswith("time limit of 0.5 s reached: the best plan found")
    assert "HiGHS Status" not in plan.message and "\n" not in plan.message
    _stopped_by_the_clock(monkeypatch, with_plan=False)
    with pytest.raises(RuntimeError) as info:
        HybridMPC(tiny, 3, time_limit=0.5).solve([0.0, 0.0], [0.5])
    message = str(info.value)
    assert message.startswith("HiGHS found no plan within the time limit of 0.5 s")
    assert "raise time_limit or shorten the horizon" in message
    assert "HiGHS Status" not in message and "\n" not in message
    monkeypatch.undo()
    plan = HybridMPC(tiny, 3).solve([0.0, 0.0], [0.5])
    assert plan.optimal and plan.message == "optimal (relative MIP gap 1e-06)"
