"""Stability of a PWA state-space model's modes: spectral radii and a common quadratic
Lyapunov function.

Each mode's linear part A_i is checked first: a mode with spectral radius ρ(A_i) ≥ 1 is not
stable on its own, and no common quadratic function exists. Otherwise a common quadratic
Lyapunov function V(x) = xᵀPx is searched by a linear matrix inequality (LMI),

    P ⪰ I,    A_iᵀ P A_i − P ⪯ −I  for every mode i,    minimise λ_max(P),

(homogeneous in P, so "⪯ −I" is the strict inequality up to scale; the objective keeps the
certificate well conditioned), solved by cvxpy with Clarabel (SCS if Clarabel fails). The
solution is then checked in floating point: the verdict is *certified* only when the
eigenvalues confirm both inequalities.

What a certificate proves: with γ = max_i ‖A_i‖_P < 1 (the largest contraction of V's norm
over the modes), x⁺ = A_σ x is exponentially stable under *arbitrary* switching, so the PWA
model x⁺ = A_i x + B_i u + f_i, whatever its regions, keeps ‖x‖_P within
max ‖B_i u + f_i‖_P / (1 − γ) for bounded inputs once the initial state has decayed (the
affine terms f_i move the equilibria; they do not make the model unstable). Not certified
means no *common quadratic* function was found: the model may still be stable (a
piecewise-quadratic function over the regions is a weaker requirement, not searched here).
"""

from dataclasses import dataclass, field

import numpy as np

#: Solvers tried in turn for the LMI (both are installed with cvxpy).
SOLVERS = ("CLARABEL", "SCS")


@dataclass(frozen=True)
class StabilityReport:
    """The verdict of :func:`stability_report`.

    Attributes
    ----------
    spectral_radius : ndarray of shape (s,)
        ρ(A_i) of each mode.
    certified : bool
        Whether the linear parts share a quadratic Lyapunov function (checked in floating
        point).
    method : str
        The test that decided: ``"common quadratic Lyapunov function (LMI, <solver>)"``,
        or ``"spectral radius"`` when a mode has ρ(A_i) ≥ 1 (no LMI is then solved).
    message : str
        The verdict in a sentence.
    P : ndarray of shape (n, n) or None
        The certificate V(x) = xᵀPx (certified only).
    contraction : float or None
        γ = max_i ‖A_i‖_P = max_i sqrt(λ_max(P⁻¹A_iᵀPA_i)) < 1 (certified only).
    certificates : dict
        The matrices of the certificate by name (``{"P": P}``; empty when not certified).
    """

    spectral_radius: np.ndarray
    certified: bool
    method: str
    message: str
    P: np.ndarray | None = None
    contraction: float | None = None
    certificates: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The report as JSON-ready Python objects."""
        return {"spectral_radius": self.spectral_radius.tolist(), "certified": self.certified,
                "method": self.method, "message": self.message,
                "contraction": self.contraction,
                "certificates": {k: v.tolist() for k, v in self.certificates.items()}}


def _solve_lmi(A: np.ndarray, solver: str):
    import cvxpy as cp

    n = A.shape[1]
    P = cp.Variable((n, n), symmetric=True)
    t = cp.Variable()
    eye = np.eye(n)
    cons = [P >> eye, P << t * eye]
    for Ai in A:
        lhs = Ai.T @ P @ Ai - P
        cons.append((lhs + lhs.T) / 2 << -eye)
    problem = cp.Problem(cp.Minimize(t), cons)
    try:
        problem.solve(solver=solver)
    except cp.error.SolverError:
        return None
    if problem.status not in ("optimal", "optimal_inaccurate") or P.value is None:
        return None
    return (P.value + P.value.T) / 2


def _verified(A: np.ndarray, P: np.ndarray) -> float | None:
    """γ = max_i ‖A_i‖_P when P ≻ 0 and every A_iᵀPA_i − P ≺ 0 in floating point, else
    None."""
    w, V = np.linalg.eigh(P)
    if w.min() <= 0:
        return None
    scale = w.max()
    if max(np.linalg.eigvalsh(Ai.T @ P @ Ai - P).max() for Ai in A) >= -1e-9 * scale:
        return None
    root = V @ np.diag(np.sqrt(w)) @ V.T
    inv_root = V @ np.diag(1 / np.sqrt(w)) @ V.T
    return float(max(np.linalg.norm(root @ Ai @ inv_root, 2) for Ai in A))


def stability_report(ss, solvers: tuple[str, ...] = SOLVERS) -> StabilityReport:
    """Spectral radius of each mode and a search for a common quadratic Lyapunov function
    of the linear parts A_i (see the module doc).

    Parameters
    ----------
    ss : PWAStateSpace
    solvers : tuple of str, default ("CLARABEL", "SCS")
        cvxpy solvers tried in turn.

    Returns
    -------
    StabilityReport
    """
    A = ss.A
    rho = np.array([np.abs(np.linalg.eigvals(Ai)).max() if Ai.size else 0.0 for Ai in A])
    if np.any(rho >= 1):
        bad = np.flatnonzero(rho >= 1)
        return StabilityReport(
            rho, False, "spectral radius",
            f"not certified: mode(s) {bad.tolist()} have spectral radius ≥ 1 "
            f"(largest {rho.max():.4g}); no common quadratic Lyapunov function exists")
    for solver in solvers:
        P = _solve_lmi(A, solver)
        if P is None:
            continue
        gamma = _verified(A, P)
        if gamma is not None:
            method = f"common quadratic Lyapunov function (LMI, {solver})"
            return StabilityReport(
                rho, True, method,
                f"certified: V(x) = xᵀPx decreases in every mode (contraction "
                f"{gamma:.4g} per step), stable under arbitrary switching",
                P=P, contraction=gamma, certificates={"P": P})
    return StabilityReport(
        rho, False, f"common quadratic Lyapunov function (LMI, {'/'.join(solvers)})",
        "not certified: every mode is stable on its own (spectral radius "
        f"{rho.max():.4g} at most) but no common quadratic Lyapunov function was found; "
        "the model may still be stable")
