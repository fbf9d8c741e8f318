"""H-polyhedra {z : H z ≤ h} inside a box: emptiness and redundant rows by linear programs.

The regions of a PWA state-space model live in z = [x; u], whose coordinates can have very
different units (a robot's joint angles beside its torques). Every program here therefore runs
in the box's own coordinates z̃ = (z − c) / w, where c is the box's centre and w its
half-widths, so that the box is [−1, 1]ⁿ and one tolerance serves every coordinate; each row
is scaled to unit Euclidean norm there, so that H̃ z̃ − h̃ is a signed distance in those units.
The linear programs are solved by HiGHS (``scipy.optimize.linprog(method="highs")``).
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from .._typing import Float2D

#: Chebyshev radius (in box half-widths) at or below which a polyhedron counts as empty: it
#: holds no ball of that radius, so it is a boundary between regions or nothing at all.
EMPTY_RADIUS = 1e-7

#: A row is redundant when the rest of the polyhedron keeps its left side within this
#: distance (in box half-widths) of its bound.
REDUNDANCY_TOL = 1e-9


@dataclass(frozen=True)
class Box:
    """An axis-aligned box lower ≤ z ≤ upper with lower < upper in every coordinate.

    Attributes
    ----------
    lower, upper : ndarray of shape (p,)
    """

    lower: np.ndarray
    upper: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        """c = (lower + upper) / 2."""
        return (self.lower + self.upper) / 2

    @property
    def half_width(self) -> np.ndarray:
        """w = (upper − lower) / 2."""
        return (self.upper - self.lower) / 2

    def rows(self) -> tuple[Float2D, np.ndarray]:
        """The box as 2p rows (I; −I) z ≤ (upper; −lower)."""
        p = self.lower.size
        return np.vstack([np.eye(p), -np.eye(p)]), np.concatenate([self.upper, -self.lower])

    def to_unit(self, H: Float2D, h: np.ndarray) -> tuple[Float2D, np.ndarray]:
        """Rows H z ≤ h in the box's coordinates z̃ = (z − c) / w, scaled to unit norm.

        A row whose left side vanishes there is returned as zeros (a constant condition:
        always true when its bound is ≥ 0, never otherwise)."""
        Ht = H * self.half_width
        ht = h - H @ self.centre
        norm = np.linalg.norm(Ht, axis=1)
        scale = np.where(norm > 0, norm, 1.0)
        return Ht / scale[:, None], ht / scale

    def from_unit(self, Ht: Float2D, ht: np.ndarray) -> tuple[Float2D, np.ndarray]:
        """Rows H̃ z̃ ≤ h̃ of the box's coordinates back in z: H = H̃ / w, h = h̃ + H c."""
        H = Ht / self.half_width
        return H, ht + H @ self.centre


def chebyshev_ball(Ht: Float2D, ht: np.ndarray) -> tuple[float, np.ndarray | None]:
    """The largest ball inside {z̃ : H̃ z̃ ≤ h̃} ∩ [−1, 1]ⁿ (rows of unit norm): its radius,
    capped at 1, and its centre; (−1, None) when the set is empty.

    Parameters
    ----------
    Ht : ndarray of shape (k, p)
        Rows in the box's coordinates, each of unit norm or zero.
    ht : ndarray of shape (k,)
    """
    p = Ht.shape[1]
    if np.any((np.linalg.norm(Ht, axis=1) == 0) & (ht < 0)):
        return -1.0, None  # a constant condition that never holds
    # variables (z̃, r): maximise r subject to H̃ z̃ + r ≤ h̃, |z̃_c| + r ≤ 1, r ≤ 1
    A = np.vstack([np.column_stack([Ht, np.ones(len(ht))]),
                   np.column_stack([np.eye(p), np.ones(p)]),
                   np.column_stack([-np.eye(p), np.ones(p)])])
    b = np.concatenate([ht, np.ones(2 * p)])
    c = np.zeros(p + 1)
    c[-1] = -1.0
    bounds = [(None, None)] * p + [(None, 1.0)]
    res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
    if res.status == 2:  # infeasible: even a negative radius does not fit
        return -1.0, None
    if res.status != 0:
        raise RuntimeError(f"the Chebyshev-ball linear program failed: {res.message}")
    return float(res.x[-1]), res.x[:-1]


def shaping_by_rays(Ht: Float2D, ht: np.ndarray, interior: np.ndarray, n_rays: int = 2000,
                    seed: int = 0) -> np.ndarray:
    """Rows shown to shape the polyhedron by shooting rays from an interior point.

    Along a ray from a point inside, the first row the ray meets is a facet: just beyond
    that point only that row is violated, so no other rows imply it. A row counts only when
    the ray meets it alone (the next row farther on by a violation of more than
    `REDUNDANCY_TOL`), so equal rows are left to the linear programs. Rays: the rows'
    normals, the coordinate axes both ways, and ``n_rays`` random directions.

    Returns
    -------
    ndarray of bool, shape (k,)
        True for the rows shown to shape it (the others are undecided).
    """
    k, p = Ht.shape
    rng = np.random.default_rng(seed)
    d = np.vstack([Ht, np.eye(p), -np.eye(p), rng.standard_normal((n_rays, p))])
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    slack = ht - Ht @ interior  # > 0 inside
    speed = Ht @ d.T  # (k, rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(speed > 1e-12, slack[:, None] / speed, np.inf)
    order = np.argsort(t, axis=0)[:2]
    first, second = order[0], order[1] if k > 1 else order[0]
    cols = np.arange(d.shape[0])
    t1, t2 = t[first, cols], t[second, cols] if k > 1 else np.full(d.shape[0], np.inf)
    alone = np.isfinite(t1) & ((t2 - t1) * speed[first, cols] > REDUNDANCY_TOL)
    shaping = np.zeros(k, bool)
    shaping[first[alone]] = True
    return shaping


def irredundant_rows(Ht: Float2D, ht: np.ndarray, protected: np.ndarray | None = None,
                     interior: np.ndarray | None = None) -> np.ndarray:
    """The rows of a non-empty bounded polyhedron {z̃ : H̃ z̃ ≤ h̃} that shape it.

    Row k is redundant when max H̃_k z̃ over the other kept rows (with row k itself relaxed by
    1, which keeps the program bounded) stays within `REDUNDANCY_TOL` of h̃_k. Rows are
    tested in order and a redundant one is removed at once, so of two equal rows the later
    stays. Given a point inside, rows that rays from it show to shape the set
    (`shaping_by_rays`) need no program.

    Parameters
    ----------
    Ht : ndarray of shape (k, p)
        Rows of unit norm in the box's coordinates, the box's own rows among them (so the
        polyhedron is bounded).
    ht : ndarray of shape (k,)
    protected : ndarray of bool, shape (k,), optional
        Rows known to shape the polyhedron (not tested).
    interior : ndarray of shape (p,), optional
        A point strictly inside (e.g. the centre of `chebyshev_ball`).

    Returns
    -------
    ndarray of bool, shape (k,)
        The rows kept.
    """
    keep = np.ones(len(ht), bool)
    zero = np.linalg.norm(Ht, axis=1) == 0
    keep[zero] = False  # 0 ≤ h̃ with h̃ ≥ 0 (the polyhedron is not empty)
    protected = np.zeros(len(ht), bool) if protected is None else protected.copy()
    if interior is not None and np.all(Ht[~zero] @ interior < ht[~zero]):
        protected[~zero] |= shaping_by_rays(Ht[~zero], ht[~zero], interior)
    for k in range(len(ht)):
        if not keep[k] or protected[k]:
            continue
        b = np.where(np.arange(len(ht)) == k, ht + 1.0, ht)[keep]
        res = linprog(-Ht[k], A_ub=Ht[keep], b_ub=b, bounds=[(None, None)] * Ht.shape[1],
                      method="highs")
        if res.status != 0:
            raise RuntimeError(f"the redundancy linear program of row {k} failed: "
                               f"{res.message}")
        if -res.fun <= ht[k] + REDUNDANCY_TOL:
            keep[k] = False
    return keep
