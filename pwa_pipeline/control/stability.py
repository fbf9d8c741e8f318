"""Stability of a PWA state-space model's linear parts: spectral radii, a common quadratic
Lyapunov function and, failing that, a piecewise-quadratic one over the regions.

The verdict is about the **linear parts**: the switched linear system x⁺ = A_σ x, under
arbitrary switching for the common function and under the switching the regions allow for
the piecewise one. The affine terms B_i u + f_i are treated as inputs (see "What a
certificate proves" below); no equilibrium of the affine model is analysed.

Three tests, in turn:

1. **Spectral radius.** ρ(A_i) of each mode. A model of one mode (a linear model) is
   decided here: ρ(A) < 1 is exactly the exponential stability of x⁺ = A x, and the
   discrete Lyapunov equation AᵀPA − P = −I (solved directly, no LMI solver) gives its
   certificate (method ``"spectral radius"``). A mode with ρ(A_i) ≥ 1 (within
   `MARGINAL`) rules a common quadratic function out. If such a mode can also follow
   itself (its region holds a point [x; u] whose successor, with some next input, is in the
   same region: a linear program, below), no piecewise-quadratic function of the form of
   test 3 exists either, and the report stops there (method ``"spectral radius"``). This is
   where the robot's models of the sets ``paper`` and ``robot`` end, in a fraction of a
   second.
2. **Common quadratic function** V(x) = xᵀPx, when every ρ(A_i) < 1: the LMI

       P ⪰ I,    A_iᵀ P A_i − P ⪯ −I  for every mode i,    minimise λ_max(P)

   (homogeneous in P, so "⪯ −I" is the strict inequality up to scale; the objective keeps
   the certificate well conditioned).
3. **Piecewise-quadratic function** V(x) = xᵀP_i x while the model is in mode i, in the
   discrete-time form of Mignone, Ferrari-Trecate & Morari (2000) (the switched Lyapunov
   function of Daafouz, Riedinger & Iung (2002) with the switching restricted by the
   regions, as Johansson & Rantzer (1998) restrict it in continuous time): the LMI

       P_i ⪰ I,    A_iᵀ P_j A_i − P_i ⪯ −I  for every transition (i, j),
       minimise max_i λ_max(P_i),

   where (i, j) is a **transition** unless a linear program proves that no step can take
   the model from region i to region j: no z = [x; u] in P_i and in the envelope has a
   successor x⁺ = A_i x + B_i u + f_i that, with some input u⁺ in the envelope, gives
   [x⁺; u⁺] in P_j and in the envelope (`transitions`; every row relaxed by
   `SLACK` half-widths of the envelope, so a pair that only touches is kept). The
   model is not defined outside its envelope, so every step it takes is one of these
   transitions; with every pair kept this is the standard condition for arbitrary
   switching.

Both LMIs are solved by cvxpy with Clarabel (SCS if Clarabel fails) and the solution is
checked in floating point: the verdict is **certified** only when the eigenvalues confirm
P_i ≻ 0 and A_iᵀP_jA_i − P_i ≺ 0 (below −1e-9 λ_max) for every mode or transition. A solver
that stops without a solution is named with what happened in a few words (`SOLVER_OUTCOMES`),
never with the solver's own text, which is meant for whoever tunes the solver.

What a certificate proves: with γ = max ‖A_i‖ from P_i to P_j over the transitions (the
largest contraction per step, ‖P_j^{1/2} A_i P_i^{−1/2}‖₂ < 1), the switched linear system
x⁺ = A_σ x is exponentially stable for every mode sequence the regions allow (every sequence
for a common P). For the PWA model x⁺ = A_i x + B_i u + f_i this means: two trajectories
driven by the same inputs through the same modes converge at rate γ, and along any
trajectory ‖x(k)‖_{P_σ(k)} ≤ γᵏ ‖x(0)‖_{P_σ(0)} + max ‖B_i u + f_i‖_{P_j} / (1 − γ), so the
state forgets its initial value and stays within a bound set by the inputs (the affine terms
f_i move the equilibria; they do not make the model unstable). **Not certified** means that
no function of these forms was found (or the search was skipped, which the message says):
the model may still be stable.

Time. The LMIs hold (number of modes or transitions) × (n(n+1)/2)² coefficients, which for
the robot's models (27 modes, n = 24) is far beyond what an interior-point solver takes in
seconds. A search whose LMI exceeds ``max_lmi_size`` coefficients is skipped, and the whole
report keeps to ``max_seconds`` (the solver's time limit is what is left of it), each with a
message saying so.

References
----------
M. Johansson and A. Rantzer, "Computation of piecewise quadratic Lyapunov functions for
hybrid systems", *IEEE Transactions on Automatic Control* 43(4), 555–559, 1998.

D. Mignone, G. Ferrari-Trecate and M. Morari, "Stability and stabilization of piecewise
affine and hybrid systems: an LMI approach", *Proceedings of the 39th IEEE Conference on
Decision and Control*, 504–509, 2000.

J. Daafouz, P. Riedinger and C. Iung, "Stability analysis and control synthesis for switched
systems: a switched Lyapunov function approach", *IEEE Transactions on Automatic Control*
47(11), 1883–1887, 2002.
"""

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_discrete_lyapunov
from scipy.optimize import linprog

from .._optional import require
from .polyhedra import Box

#: Solvers tried in turn for the LMIs (both are installed with cvxpy).
SOLVERS = ("CLARABEL", "SCS")

#: The report's time budget in seconds by default (the issue's target is 30 s; the rest is
#: margin for what the solver's time limit does not cover, building the problem).
MAX_SECONDS = 20.0

#: Largest LMI searched by default, in coefficients: (modes or transitions) × (n(n+1)/2)².
#: About 10 s of Clarabel on two cores (e.g. 16 transitions of 24 × 24 blocks, or 256 of
#: 12 × 12; 22 of 24 × 24, 2 million coefficients, take 13 s).
MAX_LMI_SIZE = 1_500_000

#: A mode whose spectral radius is within this of 1 counts as ρ ≥ 1: an integrator computed
#: in floating point may come out a hair below 1, and no certificate could be verified at
#: that margin.
MARGINAL = 1e-9

#: What a solver's status means, in the words of the report's message (any other status:
#: "stopped without a solution"); ``"solver_error"`` is a solver that raised.
SOLVER_OUTCOMES = {
    "user_limit": "time limit reached",
    "solver_error": "failed numerically",
    "infeasible": "no such function (infeasible)",
    "infeasible_inaccurate": "no such function (infeasible, inaccurate)",
    "unbounded": "failed numerically (unbounded)",
    "unbounded_inaccurate": "failed numerically (unbounded)",
}

#: Every row of a transition's linear program is relaxed by this much (half-widths of the
#: envelope), so that a transition is excluded only when it is clearly impossible.
SLACK = 1e-6


@dataclass(frozen=True)
class StabilityReport:
    """The verdict of [`stability_report`][pwa_pipeline.control.stability_report].

    Attributes
    ----------
    spectral_radius : ndarray of shape (s,)
        ρ(A_i) of each mode.
    certified : bool
        Whether a common or a piecewise-quadratic Lyapunov function of the linear parts was
        found and confirmed in floating point (see the module doc for what that proves).
    method : str
        The test that decided: ``"common quadratic Lyapunov function (LMI, <solver>)"``,
        ``"piecewise quadratic Lyapunov function (LMI over k transitions, <solver>)"``, or
        ``"spectral radius"`` for a one-mode model or when a mode with ρ(A_i) ≥ 1 can
        follow itself (no LMI is then solved). A search that was skipped says
        ``"(not searched: …)"``.
    message : str
        The verdict in a sentence, with the reason when not certified.
    P : ndarray of shape (n, n) or None
        The common certificate V(x) = xᵀPx (certified by the common function, or by the
        spectral radius of a one-mode model, only).
    contraction : float or None
        γ = max ‖P_j^{1/2} A_i P_i^{−1/2}‖₂ < 1 over the modes (common P: P_i = P_j = P) or
        the transitions (certified only).
    certificates : dict
        The certificate's matrices by name: ``{"P": P}`` for a common function,
        ``{"P1": P_1, "P2": P_2, …}`` (mode i's matrix as ``P{i+1}``, numbered as the MPT3
        script numbers the modes) for a piecewise one; empty when not certified.
    transitions : ndarray of int, shape (k, 2), or None
        The pairs (i, j) of modes a step can go between (`transitions`), when the
        piecewise search computed them.
    """

    spectral_radius: np.ndarray
    certified: bool
    method: str
    message: str
    P: np.ndarray | None = None
    contraction: float | None = None
    certificates: dict = field(default_factory=dict)
    transitions: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The report as JSON-ready Python objects."""
        return {"spectral_radius": self.spectral_radius.tolist(), "certified": self.certified,
                "method": self.method, "message": self.message,
                "contraction": self.contraction,
                "certificates": {k: v.tolist() for k, v in self.certificates.items()},
                "transitions": None if self.transitions is None
                else self.transitions.tolist()}


# --- transitions between regions --------------------------------------------------------

def transitions(ss, pairs=None, deadline: float | None = None,
                slack: float = SLACK) -> np.ndarray | None:
    """Which pairs of modes (i, j) a step of the model can go between.

    (i, j) is excluded only when a linear program (HiGHS) shows that no z = [x; u] in
    region i and in the envelope has a successor x⁺ = A_i x + B_i u + f_i such that
    [x⁺; u⁺] lies in region j and in the envelope for some input u⁺. The program runs in
    the envelope's coordinates (`Box`) with every row
    relaxed by ``slack`` half-widths, so rounding never excludes a pair; a program that
    does not finish cleanly keeps its pair.

    Parameters
    ----------
    ss : PWAStateSpace
    pairs : iterable of (int, int), optional
        The pairs to test; default every (i, j).
    deadline : float, optional
        A `time.perf_counter` value; past it the function gives up and returns None.
    slack : float, default SLACK

    Returns
    -------
    ndarray of bool, shape (s, s), or None
        ``possible[i, j]`` for the pairs tested (False for those not tested); None when the
        deadline passed first.
    """
    s, n, r = ss.n_modes, ss.n_states, ss.n_inputs
    box = Box(*ss.envelope)
    c, w = box.centre, box.half_width
    unit = [box.to_unit(H, h) for H, h in ss.regions]
    possible = np.zeros((s, s), bool)
    if pairs is None:
        pairs = [(i, j) for i in range(s) for j in range(s)]
    successor: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for i, j in pairs:
        if deadline is not None and time.perf_counter() > deadline:
            return None
        if i not in successor:
            # x̃⁺ = M z̃ + m: mode i's step in the envelope's coordinates
            G = np.hstack([ss.A[i], ss.B[i]])
            successor[i] = (G * w / w[:n, None], (G @ c + ss.f[i] - c[:n]) / w[:n])
        M, m = successor[i]
        Hi, hi = unit[i]
        Hj, hj = unit[j]
        Hx, Hu = Hj[:, :n], Hj[:, n:]
        A_ub = np.vstack([np.hstack([Hi, np.zeros((len(hi), r))]),
                          np.hstack([Hx @ M, Hu]),
                          np.hstack([M, np.zeros((n, r))]),
                          np.hstack([-M, np.zeros((n, r))])])
        b_ub = np.concatenate([hi + slack, hj - Hx @ m + slack, 1 + slack - m, 1 + slack + m])
        res = linprog(np.zeros(n + 2 * r), A_ub=A_ub, b_ub=b_ub,
                      bounds=[(-1 - slack, 1 + slack)] * (n + 2 * r), method="highs")
        possible[i, j] = res.status != 2  # 2: infeasible
    return possible


# --- the LMIs ---------------------------------------------------------------------------

def _duplication(n: int) -> np.ndarray:
    """D of shape (n², n(n+1)/2): vec(P) = D p for a symmetric P and its upper triangle p."""
    rows, cols = np.triu_indices(n)
    D = np.zeros((n * n, rows.size))
    D[rows * n + cols, np.arange(rows.size)] = 1.0
    D[cols * n + rows, np.arange(rows.size)] = 1.0
    return D


def lmi_size(n: int, conditions: int) -> int:
    """Coefficients of an LMI of ``conditions`` decrease conditions on n × n blocks, each
    dense in its unknown's n(n+1)/2 entries: the measure ``max_lmi_size`` bounds."""
    return conditions * (n * (n + 1) // 2) ** 2


def _solve_lmi(A: np.ndarray, pairs: list[tuple[int, int]], blocks: list[int], solver: str,
               seconds: float) -> tuple[list[np.ndarray] | None, str]:
    """Solve P_b ⪰ I, P_b ⪯ tI, A_iᵀ P_{b(j)} A_i − P_{b(i)} ⪯ −I for every pair, minimising
    t, with P_{b(i)} the unknown of mode i's block (one block for a common P).

    The unknowns are the upper triangles p_b, and vec(A_iᵀ P A_i) = (A_iᵀ ⊗ A_iᵀ) D p is
    formed in numpy, so cvxpy sees one matrix product per condition (far quicker to compile
    than the matrix expression). Returns (P of each mode, solver status), P None unless
    solved; the status is cvxpy's, or ``"solver_error"`` when the solver raised."""
    cp = require("cvxpy", "control", "The stability report's Lyapunov search")

    n = A.shape[1]
    D = _duplication(n)
    p = [cp.Variable(D.shape[1]) for _ in range(max(blocks) + 1)]
    t = cp.Variable()
    eye = np.eye(n)
    P = [cp.reshape(D @ v, (n, n), order="C") for v in p]
    cons = [c for Pb in P for c in (Pb >> eye, Pb << t * eye)]
    kron: dict[int, np.ndarray] = {}
    for i, j in pairs:
        if i not in kron:
            kron[i] = np.kron(A[i].T, A[i].T) @ D
        decrease = cp.reshape(kron[i] @ p[blocks[j]], (n, n), order="C") - P[blocks[i]]
        cons.append(decrease << -eye)
    problem = cp.Problem(cp.Minimize(t), cons)
    limit = {"CLARABEL": {"time_limit": seconds},
             "SCS": {"time_limit_secs": seconds}}.get(solver, {})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "solution may be inaccurate": checked below
        try:
            problem.solve(solver=solver, **limit)
        except cp.error.SolverError:  # its text names options for tuning, not the reason
            return None, "solver_error"
    if problem.status not in ("optimal", "optimal_inaccurate") \
            or any(v.value is None for v in p):
        return None, str(problem.status)
    mats = [(D @ v.value).reshape(n, n) for v in p]
    return [mats[blocks[i]] for i in range(len(blocks))], str(problem.status)


def _verified(A: np.ndarray, P: list[np.ndarray],
              pairs: list[tuple[int, int]]) -> float | None:
    """γ = max over pairs of ‖P_j^{1/2} A_i P_i^{−1/2}‖₂ when every P_i ≻ 0 and every
    A_iᵀP_jA_i − P_i ≺ 0 (below −1e-9 of the largest eigenvalue of the P_i) in floating
    point, else None."""
    roots, inverse_roots, top = {}, {}, 0.0
    for i in range(len(P)):
        w, V = np.linalg.eigh(P[i])
        if w.min() <= 0:
            return None
        top = max(top, w.max())
        roots[i] = V @ np.diag(np.sqrt(w)) @ V.T
        inverse_roots[i] = V @ np.diag(1 / np.sqrt(w)) @ V.T
    for i, j in pairs:
        if np.linalg.eigvalsh(A[i].T @ P[j] @ A[i] - P[i]).max() >= -1e-9 * top:
            return None
    return float(max((np.linalg.norm(roots[j] @ A[i] @ inverse_roots[i], 2)
                      for i, j in pairs), default=0.0))


def _search(A, pairs, blocks, solvers, deadline, max_lmi_size, what):
    """Run one LMI through the solvers within the budget.

    Returns (P of each mode, γ, solver, None) when certified; else (None, None, reason,
    skipped), ``skipped`` naming why no solver ran ("size", "time" or "solver") or
    None."""
    n = A.shape[1]
    size = lmi_size(n, len(pairs))
    if size > max_lmi_size:
        return None, None, (
            f"its LMI ({len(pairs)} {what} of {n} × {n} blocks) would hold {size:,} "
            f"coefficients, more than max_lmi_size = {max_lmi_size:,}"), "size"
    reasons = []
    for solver in solvers:
        left = deadline - time.perf_counter()
        if left <= 0:
            reasons.append("the time budget max_seconds was spent")
            break
        P, status = _solve_lmi(A, pairs, blocks, solver, left)
        if P is None:
            reasons.append(f"{solver}: "
                           f"{SOLVER_OUTCOMES.get(status, 'stopped without a solution')}")
            continue
        gamma = _verified(A, P, pairs)
        if gamma is not None:
            return P, gamma, solver, None
        reasons.append(f"{solver}: its solution fails the check in floating point")
    if not reasons:
        return None, None, "no solver was given", "solver"
    if reasons == ["the time budget max_seconds was spent"]:
        return None, None, reasons[0], "time"
    return None, None, "; ".join(reasons), None


# --- the report -------------------------------------------------------------------------

def _contraction(gamma: float) -> str:
    """γ for a message: ``0.9459``, or ``1 − 6.1e-08`` when it is within 1e-3 of 1."""
    return f"1 − {1 - gamma:.2g}" if gamma > 0.999 else f"{gamma:.4g}"


def spectral_radii(A) -> np.ndarray:
    """ρ(A_i), the largest eigenvalue modulus of each mode's state matrix A_i (0 for a
    model without states)."""
    return np.array([np.abs(np.linalg.eigvals(Ai)).max() if Ai.size else 0.0 for Ai in A])


def stability_report(ss, solvers: tuple[str, ...] = SOLVERS, max_seconds: float = MAX_SECONDS,
                     max_lmi_size: int = MAX_LMI_SIZE) -> StabilityReport:
    """Each mode's spectral radius, and a common or else a piecewise-quadratic Lyapunov
    function of the linear parts A_i (see the module doc for the tests and what a
    certificate proves).

    Parameters
    ----------
    ss : PWAStateSpace
    solvers : tuple of str, default ("CLARABEL", "SCS")
        cvxpy solvers tried in turn for each LMI.
    max_seconds : float, default MAX_SECONDS
        Time budget of the report: the transitions' linear programs stop past it and each
        solver is given what is left as its time limit; a search without time left is
        skipped and the message says so.
    max_lmi_size : int, default MAX_LMI_SIZE
        A search whose LMI holds more coefficients ((modes or transitions) ×
        (n(n+1)/2)², `lmi_size`) is skipped, and the message says so.

    Returns
    -------
    StabilityReport
    """
    deadline = time.perf_counter() + max_seconds
    A, s = ss.A, ss.n_modes
    rho = spectral_radii(A)
    marginal = np.flatnonzero(rho >= 1 - MARGINAL)
    every = "/".join(solvers)

    # 1-2. spectral radii (which decide a one-mode model); the common quadratic function
    # when every mode is stable
    if s == 1 and len(marginal) == 0:
        return _one_stable_mode(rho, A)
    if len(marginal) == 0:
        P, gamma, how, skipped = _search(A, [(i, i) for i in range(s)], [0] * s, solvers,
                                         deadline, max_lmi_size, "modes")
        if P is not None:
            return StabilityReport(
                rho, True, f"common quadratic Lyapunov function (LMI, {how})",
                "certified: V(x) = xᵀPx decreases in every mode (contraction "
                f"{_contraction(gamma)} per step), stable under arbitrary switching",
                P=P[0], contraction=gamma, certificates={"P": P[0]})
        common = (f"the common quadratic search was skipped: {how}" if skipped
                  else f"no common quadratic Lyapunov function was found ({how})")
    else:
        common = (f"mode(s) {marginal.tolist()} have spectral radius ≥ 1 (largest "
                  f"{rho.max():.4g}), so no common quadratic Lyapunov function exists")

    # 3. piecewise quadratic: modes of ρ ≥ 1 that can follow themselves rule it out
    loops = transitions(ss, [(i, i) for i in marginal], deadline)
    if loops is None:
        return _skipped(rho, common, max_seconds)
    looping = [int(i) for i in marginal if loops[i, i]]
    if looping:
        return StabilityReport(
            rho, False, "spectral radius",
            f"not certified: mode(s) {looping} have spectral radius ≥ 1 (largest "
            f"{rho[looping].max():.4g}) and can follow themselves (their region holds "
            "states whose next step stays in it), so neither a common nor a "
            "piecewise-quadratic Lyapunov function exists; the model may still be stable "
            "if it leaves those regions")
    rest = [(i, j) for i in range(s) for j in range(s) if not (i == j and i in marginal)]
    possible = transitions(ss, rest, deadline)
    if possible is None:
        return _skipped(rho, common, max_seconds)
    pairs = [(int(i), int(j)) for i, j in zip(*np.nonzero(possible), strict=True)]
    graph = np.array(pairs, dtype=int).reshape(-1, 2)
    P, gamma, how, skipped = _search(A, pairs, list(range(s)), solvers, deadline,
                                     max_lmi_size, "transitions")
    method = f"piecewise quadratic Lyapunov function (LMI over {len(pairs)} transitions"
    if P is not None:
        return StabilityReport(
            rho, True, f"{method}, {how})",
            f"certified: V(x) = xᵀP_i x in mode i decreases over each of the {len(pairs)} "
            f"transitions (i, j) the regions allow, of {s * s} pairs of modes "
            f"(contraction {_contraction(gamma)} per step), so x⁺ = A_σ x is exponentially "
            f"stable under the switching the regions allow; {common}",
            contraction=gamma, transitions=graph,
            certificates={f"P{i + 1}": P[i] for i in range(s)})
    if skipped:
        why = {"size": "LMI too large", "time": "time", "solver": "no solver"}[skipped]
        return StabilityReport(
            rho, False, f"piecewise quadratic Lyapunov function (not searched: {why})",
            f"not certified: {common}; the piecewise-quadratic search over the {len(pairs)} "
            f"transitions the regions allow was skipped: {how}", transitions=graph)
    return StabilityReport(
        rho, False, f"{method}, {every})",
        f"not certified: {common}, and no piecewise-quadratic Lyapunov function over the "
        f"{len(pairs)} transitions the regions allow was found ({how}); the model may "
        "still be stable", transitions=graph)


def _one_stable_mode(rho: np.ndarray, A: np.ndarray) -> StabilityReport:
    """The report of a one-mode model x⁺ = A x with ρ(A) < 1: certified by its spectral
    radius, with the certificate P of AᵀPA − P = −I when it passes the floating-point check
    (a spectral radius a hair below 1 can leave P too ill-conditioned for it)."""
    n = A.shape[1]
    P = solve_discrete_lyapunov(A[0].T, np.eye(n))
    gamma = _verified(A, [P], [(0, 0)])
    shown = f"{rho[0]:.4g}" if rho[0] < 0.9999 else f"1 − {1 - rho[0]:.2g}"
    message = (f"certified: one mode (a linear model) of spectral radius {shown} < 1, so "
               "x⁺ = A x is exponentially stable")
    if gamma is None:
        return StabilityReport(rho, True, "spectral radius", message)
    return StabilityReport(
        rho, True, "spectral radius",
        f"{message} (V(x) = xᵀPx from AᵀPA − P = −I contracts by "
        f"{_contraction(gamma)} per step)", P=P, contraction=gamma, certificates={"P": P})


def _skipped(rho, common: str, max_seconds: float) -> StabilityReport:
    """The report when the time budget ran out before the transitions were known."""
    return StabilityReport(
        rho, False, "piecewise quadratic Lyapunov function (not searched: time)",
        f"not certified: {common}; the piecewise-quadratic search was not run: the time "
        f"budget max_seconds = {max_seconds:g} s was spent before the transitions between "
        "regions were known")
