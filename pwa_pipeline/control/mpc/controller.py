"""Hybrid model predictive control of a PWA state-space model ([`HybridMPC`][pwa_pipeline.control.HybridMPC]):
the options checked, the program of `formulation` built once, solved at each sample, and
the receding-horizon loop run on the model itself."""

import time
from dataclasses import dataclass

import numpy as np

from ..state_space import TIE_TOL, PWAStateSpace
from .formulation import MLDProgram, affine_range

#: What the input term of the cost penalises: the move u_k − u_{k−1} or the input u_k.
INPUT_PENALTIES = ("delta", "level")

#: Default share of the input weight against the output weight (both in half-widths of the
#: envelope's range of the channel).
DEFAULT_INPUT_WEIGHT = 0.1

#: The longest horizon accepted (samples). The program has one binary per mode and step,
#: (N + 1)·s, and HiGHS's branch and bound over them grows exponentially with N (an 8-mode
#: model at N = 10 took 73 s of CPU); its rows grow linearly (about 7,000 per 100 steps of
#: a 4-mode model), so N = 10⁶ built for hours before solving anything.
MAX_HORIZON = 200

#: Seconds HiGHS may take per solve unless ``time_limit`` says otherwise; when reached, the
#: best plan found is returned, not proven optimal.
DEFAULT_TIME_LIMIT = 10.0

_STATUS = {0: "optimal", 1: "time or iteration limit reached", 2: "infeasible",
           3: "unbounded", 4: "solver error"}


@dataclass
class MPCSolution:
    """The optimal plan of one [`HybridMPC.solve`][pwa_pipeline.control.HybridMPC.solve].

    Attributes
    ----------
    u : ndarray of shape (N, r)
        Inputs u_0 … u_{N−1}; u_0 is the one to apply now.
    x : ndarray of shape (N + 1, n)
        Predicted states x_0 (the given state) … x_N.
    y : ndarray of shape (N, m)
        Predicted outputs y_1 … y_N (those the inputs act on).
    modes : ndarray of int, shape (N + 1,)
        The mode of each step 0 … N (step N with the last input held).
    cost : float
        The optimal value of the cost.
    status : int
        `scipy.optimize.milp`'s status: 0 optimal, 1 time limit reached with a feasible
        plan (then ``optimal`` is False).
    message : str
        One line: ``optimal (relative MIP gap …)``, or ``time limit of … s reached: the
        best plan found, …`` (never the solver's own text).
    optimal : bool
        Whether HiGHS proved the plan optimal (to the relative MIP gap).
    seconds : float
        Wall-clock time of the solve.
    """

    u: np.ndarray
    x: np.ndarray
    y: np.ndarray
    modes: np.ndarray
    cost: float
    status: int
    message: str
    optimal: bool
    seconds: float


@dataclass
class ClosedLoop:
    """The trajectories of [`HybridMPC.closed_loop`][pwa_pipeline.control.HybridMPC.closed_loop], sample t = 0
    … steps − 1.

    Attributes
    ----------
    x : ndarray of shape (steps + 1, n)
        States x(0) … x(steps), each from the model's step.
    u : ndarray of shape (steps, r)
        The input applied at t (the first of that sample's plan).
    y : ndarray of shape (steps, m)
        The model's output at t, y(t) = C_i x(t) + g_i.
    y_ref : ndarray of shape (steps, m)
        The reference of sample t.
    modes : ndarray of int, shape (steps,)
        The mode the model took at t ([`mode_of`][pwa_pipeline.control.PWAStateSpace.mode_of]).
    cost : ndarray of shape (steps,)
        The optimal cost of each sample's plan.
    seconds : ndarray of shape (steps,)
        Wall-clock time of each sample's solve.
    """

    x: np.ndarray
    u: np.ndarray
    y: np.ndarray
    y_ref: np.ndarray
    modes: np.ndarray
    cost: np.ndarray
    seconds: np.ndarray


class HybridMPC:
    """Finite-horizon output-tracking MPC of a PWA state-space model, solved as a MILP.

    The model's dynamics, regions and envelope are constraints of a mixed-integer linear
    program in the mixed logical dynamical form of Bemporad & Morari (1999), with one binary
    per mode and step and big-M constants computed exactly from the box of z = [x; u]; the
    1-norm cost makes it a MILP that HiGHS (`scipy.optimize.milp`) solves to proven
    optimality. See the module doc for the program.

    Parameters
    ----------
    ss : PWAStateSpace
        The model, e.g. ``model.to_state_space()`` or ``PWAStateSpace.from_json(...)``.
    horizon : int
        N, the number of inputs planned (and of predicted outputs in the cost), from 1 to
        `MAX_HORIZON` (200): the program has one binary per mode and step, and HiGHS's
        search over them grows exponentially with N.
    Q : float or array-like of shape (m,), optional
        Weight of each output's absolute tracking error. Default: 1 / the half-width of the
        output's range in the envelope (so an error counts in units of that range and
        channels of different units weigh alike).
    R : float or array-like of shape (r,), optional
        Weight of each input's absolute move (or level, see ``input_penalty``). Default: 0.1 /
        the half-width of the input's range in the envelope.
    u_min, u_max : float or array-like of shape (r,), optional
        Input bounds; default the envelope's input range. They must lie inside that range,
        where the model is defined.
    input_penalty : {"delta", "level"}, default "delta"
        Penalise |u_k − u_{k−1}| (no steady offset when tracking) or |u_k|.
    mip_rel_gap : float, default 1e-6
        HiGHS's relative optimality gap: the plan's cost is within this share of the optimum.
    time_limit : float or None, default `DEFAULT_TIME_LIMIT` (10 s)
        Seconds HiGHS may take per solve (each sample of ``closed_loop`` gets its own);
        when reached, the best plan found is returned with ``optimal=False`` and a message
        saying so (a ``RuntimeError`` if none was found). None: no limit.

    Attributes
    ----------
    ss : PWAStateSpace
    horizon : int
    Q, R, u_min, u_max : ndarray
    program : MLDProgram
        The mixed-integer linear program (`formulation`: its box, big-M constants,
        mode-dependent expressions and state bounds).

    Raises
    ------
    ValueError
        If the horizon is not a whole number from 1 to `MAX_HORIZON`, the time limit is not
        a number of seconds > 0, a weight is negative or has the wrong
        shape, or an input bound is outside the envelope or above the other.

    Examples
    --------
    A state-space model of a fitted model, and x a state of it (a row of ``ss.states``):

    >>> import numpy as np
    >>> from pwa_pipeline import LinearARX
    >>> u = np.random.default_rng(0).uniform(-1, 1, size=(300, 1))
    >>> y = np.zeros((300, 1))
    >>> for k in range(1, 300):
    ...     y[k] = 0.5 * y[k - 1] + u[k - 1]
    >>> ss = LinearARX(na=1, nb=1).fit(u, y).to_state_space()
    >>> x = ss.states(u, y)[-1]
    >>> mpc = HybridMPC(ss, horizon=10)
    >>> plan = mpc.solve(x, y_ref=[1.0])              # plan.u[0] is the input to apply now
    >>> run = mpc.closed_loop(x, y_ref=[1.0], steps=20)
    >>> bool(abs(run.y[-1, 0] - 1.0) < 1e-4)
    True
    """

    def __init__(self, ss: PWAStateSpace, horizon: int, Q=None, R=None, u_min=None,
                 u_max=None, *, input_penalty: str = "delta", mip_rel_gap: float = 1e-6,
                 time_limit: float | None = DEFAULT_TIME_LIMIT):
        if not isinstance(ss, PWAStateSpace):
            raise ValueError(f"ss must be a PWAStateSpace, got {type(ss).__name__}")
        if isinstance(horizon, bool) or not isinstance(horizon, int | np.integer) or horizon < 1:
            raise ValueError(f"horizon must be a whole number >= 1, got {horizon!r}")
        if horizon > MAX_HORIZON:
            raise ValueError(
                f"horizon = {horizon} is above the limit of {MAX_HORIZON} samples: the "
                f"program would have {(int(horizon) + 1) * ss.n_modes:,} binaries (one per "
                f"mode and step), whose search HiGHS cannot finish, and building it alone "
                f"grows with the horizon; plan over fewer samples")
        if input_penalty not in INPUT_PENALTIES:
            raise ValueError(f"input_penalty must be one of {INPUT_PENALTIES}, got "
                             f"{input_penalty!r}")
        if not np.isfinite(mip_rel_gap) or mip_rel_gap < 0:
            raise ValueError(f"mip_rel_gap must be >= 0, got {mip_rel_gap!r}")
        if time_limit is not None and not time_limit > 0:
            raise ValueError(f"time_limit must be > 0 seconds, got {time_limit!r}")
        self.ss, self.horizon = ss, int(horizon)
        self.input_penalty, self.mip_rel_gap, self.time_limit = (
            input_penalty, float(mip_rel_gap), time_limit)
        n, r, m = ss.n_states, ss.n_inputs, ss.n_outputs
        lower, upper = ss.envelope
        half = (upper - lower) / 2
        if ss.lagged and ss.output_lags >= 1:
            y_half = half[np.arange(m) * ss.output_lags]
        else:  # (no output range in the envelope)
            y_half = np.ones(m)
        self.Q = self._weight(Q, 1.0 / y_half, m, "Q", "output(s)")
        self.R = self._weight(R, DEFAULT_INPUT_WEIGHT / half[n:], r, "R", "input(s)")
        self.u_min = self._input_bound(u_min, lower[n:], "u_min")
        self.u_max = self._input_bound(u_max, upper[n:], "u_max")
        if np.any(self.u_min > self.u_max):
            q = int(np.flatnonzero(self.u_min > self.u_max)[0])
            raise ValueError(f"u_min[{q}] = {self.u_min[q]:.6g} is above u_max[{q}] = "
                             f"{self.u_max[q]:.6g} (input {ss.input_names[q]}): no input "
                             f"satisfies both")
        self.program = MLDProgram(ss, self.horizon, self.Q, self.R, self.u_min, self.u_max,
                                  input_penalty)

    # --- set-up -------------------------------------------------------------------------

    @staticmethod
    def _weight(value, default: np.ndarray, size: int, name: str, what: str) -> np.ndarray:
        if value is None:
            return default.astype(float)
        w = np.asarray(value, dtype=float)
        if w.ndim == 0:
            w = np.full(size, float(w))
        if w.shape != (size,):
            raise ValueError(f"{name} must be a number or have one weight per {what[:-3]} "
                             f"({size} {what}); got shape {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"{name} must hold finite weights >= 0, got {w.tolist()}")
        return w

    def _input_bound(self, value, envelope: np.ndarray, name: str) -> np.ndarray:
        if value is None:
            return envelope.copy()
        b = np.asarray(value, dtype=float)
        if b.ndim == 0:
            b = np.full(envelope.size, float(b))
        if b.shape != envelope.shape or not np.all(np.isfinite(b)):
            raise ValueError(f"{name} must be a finite number or one per input "
                             f"({envelope.size}); got {np.asarray(value).tolist()}")
        lower, upper = self.ss.envelope
        lo, hi = lower[self.ss.n_states:], upper[self.ss.n_states:]
        outside = (b < lo) | (b > hi)
        if np.any(outside):
            q = int(np.flatnonzero(outside)[0])
            raise ValueError(
                f"{name}[{q}] = {b[q]:.6g} is outside the data envelope's range "
                f"[{lo[q]:.6g}, {hi[q]:.6g}] of input {self.ss.input_names[q]}: the model is "
                f"not defined there")
        return b

    # --- solving ------------------------------------------------------------------------

    def _state(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        n = self.ss.n_states
        if x.shape != (n,):
            raise ValueError(f"x must have shape ({n},) (states {', '.join(self.ss.state_names)}"
                             f"), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("x holds non-finite values")
        lower, upper = (b[:n] for b in self.ss.envelope)
        slack = TIE_TOL * (upper - lower)
        outside = (x < lower - slack) | (x > upper + slack)
        if np.any(outside):
            j = int(np.flatnonzero(outside)[0])
            raise ValueError(f"x is outside the data envelope: {self.ss.state_names[j]} = "
                             f"{x[j]:.6g} is not in [{lower[j]:.6g}, {upper[j]:.6g}]; the model "
                             f"is not defined there")
        return np.clip(x, lower, upper)

    def _reference(self, y_ref) -> np.ndarray:
        m, N = self.ss.n_outputs, self.horizon
        ref = np.asarray(y_ref, dtype=float)
        if ref.shape == (m,):
            ref = np.tile(ref, (N, 1))
        if ref.shape != (N, m):
            raise ValueError(f"y_ref must have shape ({m},) (a constant reference) or "
                             f"({N}, {m}) (one row per predicted output y_1 … y_N), got "
                             f"{ref.shape}")
        if not np.all(np.isfinite(ref)):
            raise ValueError("y_ref holds non-finite values")
        return ref

    def previous_input(self, x) -> np.ndarray:
        """u(k−1) as the state holds it (the entries ``u_q(k-1)``), or zeros when the state
        holds no past input (nb = 0, or a state that is not made of past values: give
        ``u_prev``); the first move of ``input_penalty="delta"`` is counted from it."""
        ss = self.ss
        x = np.asarray(x, dtype=float)
        if not ss.lagged or ss.input_lags == 0:
            return np.zeros(ss.n_inputs)
        start = ss.n_outputs * ss.output_lags
        return x[start + np.arange(ss.n_inputs) * ss.input_lags]

    def solve(self, x, y_ref, u_prev=None) -> MPCSolution:
        """The optimal inputs over the horizon from state x.

        Parameters
        ----------
        x : array-like of shape (n,)
            The current state (``ss.state_names``), inside the envelope.
        y_ref : array-like of shape (m,) or (N, m)
            The reference of the predicted outputs y_1 … y_N (one row, or one per step).
        u_prev : array-like of shape (r,), optional
            The input applied at the previous sample, from which the first move is counted
            (``input_penalty="delta"``). Default: as the state holds it
            ([`previous_input`][pwa_pipeline.control.HybridMPC.previous_input]).

        Returns
        -------
        MPCSolution

        Raises
        ------
        ValueError
            If x is outside the envelope, an argument has the wrong shape, or the problem is
            infeasible: the message gives the solver's status and the cause, i.e. the input
            bounds (naming ``u_min`` or ``u_max``), a reference outside the model's reach
            (outside `output_range`, which steering towards drives the state to the
            envelope's edge), or the envelope (the number of steps the state can be kept
            inside it from x).
        RuntimeError
            If HiGHS stops without a plan for another reason (time limit, solver error).
        """
        x, ref = self._state(x), self._reference(y_ref)
        if u_prev is None:
            u_prev = self.previous_input(x)
        u_prev = np.asarray(u_prev, dtype=float)
        if u_prev.shape != (self.ss.n_inputs,) or not np.all(np.isfinite(u_prev)):
            raise ValueError(f"u_prev must hold {self.ss.n_inputs} finite value(s), got "
                             f"{u_prev.tolist()}")
        start = time.perf_counter()
        res, v = self.program.solve(x, ref, u_prev, self.mip_rel_gap, self.time_limit)
        seconds = time.perf_counter() - start
        if v is None:
            if res.status == 2:
                raise ValueError(self._infeasible_message(x, ref))
            if res.status == 1:
                raise RuntimeError(
                    f"HiGHS found no plan within the time limit of {self.time_limit:g} s "
                    f"(horizon {self.horizon}, {self.ss.n_modes} modes: "
                    f"{(self.horizon + 1) * self.ss.n_modes} binaries); raise time_limit or "
                    f"shorten the horizon")
            raise RuntimeError(f"HiGHS stopped without a plan (status {res.status}: "
                               f"{_STATUS.get(res.status, 'unknown status')}) from x = "
                               f"{np.array2string(x, precision=4)}")
        N, n, r, m, s = (self.horizon, self.ss.n_states, self.ss.n_inputs, self.ss.n_outputs,
                         self.ss.n_modes)
        o = self.program.offsets
        delta = v[o["delta"]:o["delta"] + (N + 1) * s].reshape(N + 1, s)
        return MPCSolution(
            u=np.clip(v[o["u"]:o["u"] + N * r].reshape(N, r), self.u_min, self.u_max),
            x=v[o["x"]:o["x"] + (N + 1) * n].reshape(N + 1, n),
            y=v[o["y"]:o["y"] + N * m].reshape(N, m),
            modes=np.argmax(delta, axis=1), cost=float(res.fun), status=int(res.status),
            message=self._plan_message(res), optimal=res.status == 0, seconds=seconds)

    def _plan_message(self, res) -> str:
        """One line on how good a plan is: optimal, or the time limit reached first."""
        if res.status == 0:
            return f"optimal (relative MIP gap {self.mip_rel_gap:g})"
        gap = getattr(res, "mip_gap", None)
        return (f"time limit of {self.time_limit:g} s reached: the best plan found, not proven "
                f"optimal" + (f" (its cost within {gap:.3g} of the bound, relative)"
                              if gap is not None and np.isfinite(gap) else ""))

    def _feasible(self, x: np.ndarray, horizon: int, u_min, u_max) -> bool:
        probe = HybridMPC(self.ss, horizon, self.Q, self.R, u_min, u_max,
                          input_penalty=self.input_penalty, mip_rel_gap=1.0,
                          time_limit=self.time_limit)
        _, v = probe.program.solve(x, np.zeros((horizon, self.ss.n_outputs)),
                                   probe.previous_input(x), probe.mip_rel_gap, probe.time_limit)
        return v is not None

    def output_range(self) -> tuple[np.ndarray, np.ndarray]:
        """The range of each output over the data envelope: the smallest and largest
        C_i x + g_i of any mode i over the envelope's box of x.

        Every predicted output y_1 … y_N is such a value (its state is kept inside the
        envelope), so a reference outside this range cannot be reached from any state.

        Returns
        -------
        low, high : ndarray of shape (m,)
        """
        n, ss = self.ss.n_states, self.ss
        lower, upper = (b[:n] for b in ss.envelope)
        ranges = [affine_range(ss.C[i], ss.g[i], lower, upper) for i in range(ss.n_modes)]
        return (np.min([low for low, _ in ranges], axis=0),
                np.max([high for _, high in ranges], axis=0))

    def _infeasible_message(self, x: np.ndarray, ref: np.ndarray) -> str:
        """Why the program from x is infeasible: which input bound, a reference out of the
        model's reach, or how many steps the state can be kept inside the envelope (found by
        solving relaxed programs)."""
        ss, N = self.ss, self.horizon
        n = ss.n_states
        lower, upper = (b[n:] for b in ss.envelope)
        head = (f"the MPC problem is infeasible (HiGHS status 2, {_STATUS[2]}) from x = "
                f"{np.array2string(x, precision=4)}: ")
        tight_min, tight_max = np.any(self.u_min > lower), np.any(self.u_max < upper)

        def fmt(v):
            return np.array2string(np.asarray(v), precision=4)

        if (tight_min or tight_max) and self._feasible(x, N, None, None):
            culprits = []
            if tight_min and self._feasible(x, N, None, self.u_max):
                culprits.append(f"u_min = {fmt(self.u_min)}")
            if tight_max and self._feasible(x, N, self.u_min, None):
                culprits.append(f"u_max = {fmt(self.u_max)}")
            which = (" or ".join(culprits) if culprits
                     else f"u_min = {fmt(self.u_min)} and u_max = {fmt(self.u_max)} together")
            return (head + f"the input bounds make it so: with {which} no input sequence "
                    f"keeps the state inside the data envelope for {N} step(s); with the "
                    f"envelope's input range [{fmt(lower)}, {fmt(upper)}] one does. Widen "
                    f"the bounds or shorten the horizon")
        feasible_steps = 0
        for h in range(1, N):
            if not self._feasible(x, h, self.u_min, self.u_max):
                break
            feasible_steps = h
        kept = (f"it can for at most {feasible_steps} step(s) from this x" if feasible_steps
                else "the model's step from this x leaves it whatever the input")
        low, high = self.output_range()
        outside = (ref < low) | (ref > high)
        if np.any(outside):
            # tracking is a cost, so the reference alone never makes the program infeasible;
            # steering towards one out of reach is what brings the state to the edge
            k, p = (int(i) for i in np.argwhere(outside)[0])
            return (head + f"the reference is out of the model's reach: y_ref = "
                    f"{ref[k, p]:.6g} for output {ss.output_names[p]} (step {k + 1}) is "
                    f"outside [{low[p]:.6g}, {high[p]:.6g}], the range of its outputs over the "
                    f"data envelope. Steering towards it brings the state to the envelope's "
                    f"edge, where it cannot be kept inside for {N} more step(s) ({kept}). Set "
                    f"a reference inside that range")
        advice = ("Shorten the horizon or start" if feasible_steps else "Start")
        return (head + f"the state cannot be kept inside the data envelope for the horizon of "
                f"{N} step(s) whatever the input in [{fmt(self.u_min)}, {fmt(self.u_max)}] "
                f"and whatever the reference (a cost, not a constraint): {kept}. {advice} "
                f"from a state farther inside the envelope (in a loop, a reference near its "
                f"edge can steer the state there)")

    def closed_loop(self, x0, y_ref, steps: int, u_prev=None) -> ClosedLoop:
        """Receding-horizon control of the model itself: at each sample solve, apply the
        first input to ``ss.step``, and go on from the state it gives.

        Parameters
        ----------
        x0 : array-like of shape (n,)
            The state at sample 0.
        y_ref : array-like of shape (m,) or (T, m)
            A constant reference, or one row per sample (the plan at t uses rows
            t + 1 … t + N, the last row held beyond T).
        steps : int
            Samples to run (≥ 1).
        u_prev : array-like of shape (r,), optional
            The input before sample 0 (default: as x0 holds it); later samples count the
            first move from the input applied before.

        Returns
        -------
        ClosedLoop

        Raises
        ------
        ValueError
            As [`solve`][pwa_pipeline.control.HybridMPC.solve] (with the sample named), or if the model's step
            leaves the envelope (which a plan through a region boundary of a discontinuous model can
            do, see the module doc).
        """
        if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 1:
            raise ValueError(f"steps must be a whole number >= 1, got {steps!r}")
        m = self.ss.n_outputs
        ref = np.asarray(y_ref, dtype=float)
        if ref.shape == (m,):
            ref = ref[None, :]
        if ref.ndim != 2 or ref.shape[1] != m or ref.shape[0] == 0:
            raise ValueError(f"y_ref must have shape ({m},) or (T, {m}), got {ref.shape}")
        x = self._state(x0)
        xs, us, ys, refs, modes, costs, secs = [x], [], [], [], [], [], []
        for t in range(steps):
            window = ref[np.minimum(np.arange(t + 1, t + 1 + self.horizon), len(ref) - 1)]
            try:
                plan = self.solve(x, window, u_prev)
            except ValueError as exc:
                raise ValueError(f"at sample {t}: {exc}") from None
            u = plan.u[0]
            mode = self.ss.mode_of(x, u)
            x_next, y = self.ss.step(x, u)
            us.append(u)
            ys.append(y)
            refs.append(ref[min(t, len(ref) - 1)])
            modes.append(mode)
            costs.append(plan.cost)
            secs.append(plan.seconds)
            x, u_prev = x_next, u
            xs.append(x)
        return ClosedLoop(x=np.array(xs), u=np.array(us), y=np.array(ys), y_ref=np.array(refs),
                          modes=np.array(modes, dtype=int), cost=np.array(costs),
                          seconds=np.array(secs))

    def __repr__(self) -> str:
        return (f"HybridMPC(horizon={self.horizon}, modes={self.ss.n_modes}, "
                f"input_penalty={self.input_penalty!r})")
