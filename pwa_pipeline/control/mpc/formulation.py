"""Hybrid model predictive control of a PWA state-space model, as a mixed-integer linear program.

[`HybridMPC`][pwa_pipeline.control.HybridMPC] computes, from the state x of a
[`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace], the
inputs u(0) … u(N−1) that minimise a 1-norm tracking cost over a horizon of N samples while
the model's own dynamics, regions and data envelope hold. The PWA model is written as a mixed
logical dynamical (MLD) system (Bemporad & Morari 1999): a binary δ_{i,k} says that step k is
in mode i, and every product of a binary with an affine function of z = [x; u] is replaced by
an auxiliary variable tied to it by four linear inequalities whose constants (the "big-M")
are the exact bounds of that function over the box the variables live in. The resulting
mixed-integer linear program is solved by HiGHS through `scipy.optimize.milp`, so the
returned inputs are optimal for the model (to the relative MIP gap), not a heuristic.

**Prediction.** Step k = 0 … N has z_k = [x_k; u_k] (u_N := u_{N−1}, the last input held, so
that the mode of the last predicted output is defined) and

- Σ_i δ_{i,k} = 1, and H_i z_k − h_i ≤ M_i (1 − δ_{i,k}) for every mode i, where M_i (one
  per row) is the largest value of H_i z − h_i over the box of z: mode i only where z_k lies
  in its region P_i;
- x_{k+1} = Σ_i (A_i x_k + B_i u_k + f_i) δ_{i,k} for k < N: rows that are the same in every
  mode (the shift of the past outputs and inputs, u(k) entering the newest input lag) are
  plain equalities, the others go through auxiliary variables a_{i,k} = e_i(z_k) δ_{i,k} with
  m δ ≤ a ≤ M δ and e_i(z) − M (1 − δ) ≤ a ≤ e_i(z) − m (1 − δ), m and M the bounds of
  e_i over the box (an exact linearisation: with δ = 1 it forces a = e_i(z), with δ = 0
  a = 0);
- y_k = Σ_i (C_i x_k + g_i) δ_{i,k} likewise, for k = 1 … N (y_0 is fixed by x_0).

The box of z is the data envelope over x and [u_min, u_max] over u: every x_1 … x_N is kept
inside the envelope (the model is not defined outside it), and the inputs inside their bounds
(by default the envelope's input range).

**Cost.** Σ_{k=1}^{N} Σ_p Q_p |y_{k,p} − r_{k,p}| + Σ_{k=0}^{N−1} Σ_q R_q |Δu_{k,q}| with
Δu_k = u_k − u_{k−1} (``input_penalty="delta"``, the default: a constant reference held by a
non-zero input then costs nothing, so the loop tracks without offset), or |u_k| itself
(``"level"``). Each absolute value is an epigraph variable with two inequalities.

**Boundaries.** The regions are closed, so a z on a boundary shared by two regions satisfies
both modes' constraints and the program may take either, while
[`step`][pwa_pipeline.control.PWAStateSpace.step] takes the lowest-numbered (the fitted model's tie
rule). A prediction through a point exactly on a boundary of a discontinuous model can thus
differ from the model's step; [`HybridMPC.closed_loop`][pwa_pipeline.control.HybridMPC.closed_loop] applies
the model's own step and solves again from the state it reached.

Reference: A. Bemporad and M. Morari, "Control of systems integrating logic, dynamics, and
constraints", *Automatica* 35(3), 407–427, 1999.
"""

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import csr_array

from ..state_space import PWAStateSpace

#: Share of each state entry's half-width by which predicted states that the dynamics compute
#: keep off the envelope's faces, so that a plan within HiGHS's feasibility tolerances (1e-6
#: on the mixed-integer rows) is still inside the envelope when the model's own step is
#: applied to its first input. (Entries that copy another state entry or the input, the
#: shifted lags, need no bound of their own: the one they copy bounds them.)
STATE_MARGIN = 1e-5


def affine_range(G, q, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """The smallest and largest value of each affine function G z + q over a box.

    Exact row by row: the extreme of a linear function over a box is reached at a corner,
    coordinate by coordinate, so min = q + Σ_j min(G_j lower_j, G_j upper_j) and the same with
    max. These are the big-M constants of [`HybridMPC`][pwa_pipeline.control.HybridMPC].

    Parameters
    ----------
    G : array-like of shape (k, p)
    q : array-like of shape (k,)
    lower, upper : array-like of shape (p,)

    Returns
    -------
    low, high : ndarray of shape (k,)
    """
    G, q = np.atleast_2d(np.asarray(G, float)), np.asarray(q, float)
    lo, hi = G * np.asarray(lower, float), G * np.asarray(upper, float)
    return q + np.minimum(lo, hi).sum(axis=1), q + np.maximum(lo, hi).sum(axis=1)


class _Rows:
    """Sparse constraint rows lb ≤ A v ≤ ub, appended one at a time."""

    def __init__(self):
        self.rows, self.cols, self.vals, self.lb, self.ub = [], [], [], [], []

    def add(self, cols, vals, lb=-np.inf, ub=np.inf) -> int:
        i = len(self.lb)
        cols, vals = np.atleast_1d(cols), np.atleast_1d(np.asarray(vals, float))
        keep = vals != 0
        self.rows.extend([i] * int(keep.sum()))
        self.cols.extend(cols[keep].tolist())
        self.vals.extend(vals[keep].tolist())
        self.lb.append(lb)
        self.ub.append(ub)
        return i

    def matrix(self, n_vars: int) -> csr_array:
        return csr_array((self.vals, (self.rows, self.cols)), shape=(len(self.lb), n_vars))


class MLDProgram:
    """The mixed-integer linear program of the module doc for one model, horizon, weights
    and input bounds, built once (`solve` changes only its right-hand sides).

    Parameters
    ----------
    ss : PWAStateSpace
    horizon : int
    Q, R : ndarray of shape (m,) and (r,)
        The cost's weights.
    u_min, u_max : ndarray of shape (r,)
    input_penalty : {"delta", "level"}

    Attributes
    ----------
    box : tuple of ndarray
        (lower, upper) over z = [x; u]: the envelope over x, [u_min, u_max] over u. Every
        big-M is a bound over this box.
    region_big_m : list of ndarray
        For each mode i, max over the box of each row of H_i z − h_i (rows with a value
        ≤ 0 hold everywhere in the box and are left out of the program).
    expressions : ndarray of shape (e, s, n + r + 1)
        The mode-dependent affine functions of z (rows of [A_i B_i f_i] and of [C_i D_i g_i]
        that differ between modes, each once), coefficients over z then the constant.
    expression_bounds : tuple of ndarray
        (low, high), each of shape (e, s): their range over the box, the big-M of their
        auxiliary variables.
    state_bounds : tuple of ndarray
        (lower, upper) of shape (n,) that the predicted states x_1 … x_N keep: the envelope,
        less `STATE_MARGIN` for the entries the dynamics compute.
    offsets : dict
        Where the variables x, u, δ and y start in the solution vector.
    """

    def __init__(self, ss: PWAStateSpace, horizon: int, Q: np.ndarray, R: np.ndarray,
                 u_min: np.ndarray, u_max: np.ndarray, input_penalty: str):
        self.ss, self.horizon, self.Q, self.R = ss, horizon, Q, R
        self.u_min, self.u_max, self.input_penalty = u_min, u_max, input_penalty
        n = ss.n_states
        lower, upper = ss.envelope
        self.box = (np.concatenate([lower[:n], u_min]), np.concatenate([upper[:n], u_max]))
        self._big_m()
        self._build()

    def _big_m(self) -> None:
        """The big-M constants: each region row's and each mode-dependent expression's range
        over `box`, and which rows of the dynamics and outputs depend on the mode."""
        ss, (lower, upper) = self.ss, self.box
        n, r, m, s = ss.n_states, ss.n_inputs, ss.n_outputs, ss.n_modes
        p = n + r
        self.region_big_m = [affine_range(H, -h, lower, upper)[1] for H, h in ss.regions]
        # rows t < n: x⁺_t = [A_i B_i]_t z + f_{i,t}; rows n + j: y_j = [C_i D_i]_j z + g_{i,j}
        E = np.concatenate([
            np.concatenate([ss.A, ss.B, ss.f[:, :, None]], axis=2),
            np.concatenate([ss.C, ss.D, ss.g[:, :, None]], axis=2)], axis=1)
        self._common = np.all(E == E[:1], axis=(0, 2))  # (n + m,): the same in every mode
        self._E = E
        # state rows that copy one entry of z (x⁺_t = z_j): the shifted lags
        row = E[0, :n]
        self._copies = (self._common[:n] & (row[:, p] == 0)
                        & (np.count_nonzero(row[:, :p], axis=1) == 1)
                        & np.isin(row[:, :p], (0.0, 1.0)).all(axis=1))
        unique, self._expr_of = [], np.full(n + m, -1)
        for t in np.flatnonzero(~self._common):
            for e, known in enumerate(unique):
                if np.array_equal(known, E[:, t]):
                    self._expr_of[t] = e
                    break
            else:
                self._expr_of[t] = len(unique)
                unique.append(E[:, t])
        self.expressions = (np.array(unique) if unique else np.zeros((0, s, p + 1)))
        e_count = len(unique)
        low, high = np.zeros((e_count, s)), np.zeros((e_count, s))
        for e in range(e_count):
            low[e], high[e] = affine_range(self.expressions[e, :, :p], self.expressions[e, :, p],
                                           lower, upper)
        self.expression_bounds = (low, high)
        self._expr_for_x = np.zeros(e_count, bool)
        self._expr_for_y = np.zeros(e_count, bool)
        for t in np.flatnonzero(~self._common):
            (self._expr_for_x if t < n else self._expr_for_y)[self._expr_of[t]] = True

    def _build(self) -> None:
        """The program's constraint matrix, variable bounds and objective, built once; a solve
        changes only the right-hand sides (x_0's part, the reference, the first move)."""
        ss, N = self.ss, self.horizon
        n, r, m, s = ss.n_states, ss.n_inputs, ss.n_outputs, ss.n_modes
        p = n + r
        count = 0

        def block(size: int) -> int:
            nonlocal count
            start, count = count, count + size
            return start

        ox, ou, od = block((N + 1) * n), block(N * r), block((N + 1) * s)
        e_count = len(self.expressions)
        aux = {}
        for k in range(N + 1):
            for e in range(e_count):
                if (self._expr_for_x[e] and k < N) or (self._expr_for_y[e] and k >= 1):
                    aux[k, e] = block(s)
        oy, oty, otu = block(N * m), block(N * m), block(N * r)
        self.offsets = {"x": ox, "u": ou, "delta": od, "y": oy}

        def z_cols(k: int) -> np.ndarray:
            ku = min(k, N - 1)
            return np.concatenate([ox + k * n + np.arange(n), ou + ku * r + np.arange(r)])

        low, high = self.expression_bounds
        rows = _Rows()
        self._ref_rows = np.zeros((N, m, 2), int)
        self._first_move_rows = np.zeros((r, 2), int)
        for k in range(N + 1):
            zc, dc = z_cols(k), od + k * s + np.arange(s)
            rows.add(dc, np.ones(s), 1.0, 1.0)  # one mode per step
            for i, (H, h) in enumerate(ss.regions):
                for j in np.flatnonzero(self.region_big_m[i] > 0):
                    M = self.region_big_m[i][j]
                    rows.add(np.append(zc, dc[i]), np.append(H[j], M), ub=h[j] + M)
            for (kk, e), start in aux.items():
                if kk != k:
                    continue
                for i in range(s):
                    a, d = start + i, dc[i]
                    coef, const = self.expressions[e, i, :p], self.expressions[e, i, p]
                    lo, hi = low[e, i], high[e, i]
                    rows.add([a, d], [1.0, -hi], ub=0.0)                       # a ≤ M δ
                    rows.add([a, d], [-1.0, lo], ub=0.0)                       # a ≥ m δ
                    rows.add(np.concatenate([[a, d], zc]),                     # a ≤ e − m(1−δ)
                             np.concatenate([[1.0, -lo], -coef]), ub=const - lo)
                    rows.add(np.concatenate([[a, d], zc]),                     # a ≥ e − M(1−δ)
                             np.concatenate([[-1.0, hi], coef]), ub=hi - const)

            def tie(target: int, t: int) -> None:
                """target = row t of the dynamics/outputs at step k."""
                if self._common[t]:
                    E = self._E[0, t]
                    rows.add(np.append(zc, target), np.append(-E[:p], 1.0), E[p], E[p])
                else:
                    start = aux[k, self._expr_of[t]]
                    rows.add(np.append(start + np.arange(s), target),
                             np.append(-np.ones(s), 1.0), 0.0, 0.0)

            if k < N:
                for j in range(n):
                    tie(ox + (k + 1) * n + j, j)
            if k >= 1:
                for q in range(m):
                    yv, tv = oy + (k - 1) * m + q, oty + (k - 1) * m + q
                    tie(yv, n + q)
                    self._ref_rows[k - 1, q, 0] = rows.add([yv, tv], [1.0, -1.0], ub=0.0)
                    self._ref_rows[k - 1, q, 1] = rows.add([yv, tv], [-1.0, -1.0], ub=0.0)
            if k < N:
                for q in range(r):
                    uv, tv = ou + k * r + q, otu + k * r + q
                    if self.input_penalty == "delta" and k >= 1:
                        prev = ou + (k - 1) * r + q
                        rows.add([uv, prev, tv], [1.0, -1.0, -1.0], ub=0.0)
                        rows.add([uv, prev, tv], [-1.0, 1.0, -1.0], ub=0.0)
                    else:
                        i0 = rows.add([uv, tv], [1.0, -1.0], ub=0.0)
                        i1 = rows.add([uv, tv], [-1.0, -1.0], ub=0.0)
                        if k == 0:
                            self._first_move_rows[q] = (i0, i1)
        self._lb, self._ub = np.array(rows.lb), np.array(rows.ub)
        # x_0 is given: its columns (the first n) move to the right-hand side at each solve
        # rather than being variables fixed by their bounds, which HiGHS handles less well
        A = rows.matrix(count).tocsc()
        self._A_given = A[:, :n].toarray()
        self._A = A[:, n:].tocsr()

        lower, upper = ss.envelope
        margin = STATE_MARGIN * (upper[:n] - lower[:n]) / 2
        self.state_bounds = (np.where(self._copies, lower[:n], lower[:n] + margin),
                             np.where(self._copies, upper[:n], upper[:n] - margin))
        lb, ub = np.full(count, -np.inf), np.full(count, np.inf)
        # a copy gets no bound of its own: a second, almost equal bound on the same value is
        # what HiGHS's presolve can fail on ("Solve error")
        lb[ox:ox + (N + 1) * n] = np.tile(np.where(self._copies, -np.inf, lower[:n] + margin),
                                          N + 1)
        ub[ox:ox + (N + 1) * n] = np.tile(np.where(self._copies, np.inf, upper[:n] - margin),
                                          N + 1)
        lb[ou:ou + N * r], ub[ou:ou + N * r] = np.tile(self.u_min, N), np.tile(self.u_max, N)
        lb[od:od + (N + 1) * s], ub[od:od + (N + 1) * s] = 0.0, 1.0
        for (_, e), start in aux.items():
            lb[start:start + s] = np.minimum(low[e], 0.0)
            ub[start:start + s] = np.maximum(high[e], 0.0)
        lb[oty:], ub[oty:] = 0.0, np.inf
        integrality = np.zeros(count)
        integrality[od:od + (N + 1) * s] = 1
        c = np.zeros(count)
        c[oty:oty + N * m] = np.tile(self.Q, N)
        c[otu:otu + N * r] = np.tile(self.R, N)
        self._var_lb, self._var_ub, self._integrality, self._c = lb[n:], ub[n:], \
            integrality[n:], c[n:]

    def solve(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray, mip_rel_gap: float,
              time_limit: float | None):
        """Solve from x for the reference ``ref`` (N, m), the first move counted from
        ``u_prev``; returns HiGHS's result and the full variable vector (x_0 first), or None
        for the latter when there is no plan."""
        c_ub = self._ub.copy()
        c_ub[self._ref_rows[:, :, 0]] = ref
        c_ub[self._ref_rows[:, :, 1]] = -ref
        if self.input_penalty == "delta":
            c_ub[self._first_move_rows[:, 0]] = u_prev
            c_ub[self._first_move_rows[:, 1]] = -u_prev
        shift = self._A_given @ x
        constraints = LinearConstraint(self._A, self._lb - shift, c_ub - shift)
        options = {"disp": False, "mip_rel_gap": mip_rel_gap}
        if time_limit is not None:
            options["time_limit"] = float(time_limit)
        res = milp(self._c, integrality=self._integrality,
                   bounds=Bounds(self._var_lb, self._var_ub), constraints=constraints,
                   options=options)
        if res.status == 4:  # HiGHS's presolve can fail on a problem it solves without it
            res = milp(self._c, integrality=self._integrality,
                       bounds=Bounds(self._var_lb, self._var_ub), constraints=constraints,
                       options={**options, "presolve": False})
        return res, None if res.x is None else np.concatenate([x, res.x])
