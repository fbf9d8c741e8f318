"""Output limits: the levels an output saturates at (a sensor's range, a tank's rim), found
in the data or given.

A measured output that sits at its largest (or smallest) value for several samples in a row
has met a limit: the cascaded tanks' lower level reads exactly 10 V for 27 samples when the
tank is full. A model that does not know it simulates levels the machine cannot reach, and
its free run carries that error on. With limits lo_j ≤ hi_j, output j is predicted as

    ŷ_j(k) = min(max(Θ_{j,λ(φ(k))}ᵀ φ(k), lo_j), hi_j),

still a PWA model on polyhedral regions (eq. 1): each region H_i splits by the hyperplanes
Θ_{j,i}ᵀφ = lo_j and Θ_{j,i}ᵀφ = hi_j into the sub-model's own part and parts with the
constant model ŷ_j = lo_j or hi_j, which is how `to_state_space` exports it. The map stays
continuous across those boundaries.

``"measured"`` takes as limits the extremes that some training experiment holds for
`PLATEAU` samples or more (exactly equal values: a reading clipped by its sensor or a level
held by an overflow repeats itself; noise does not).
"""

import numpy as np

from .._typing import Float2D

#: Consecutive samples at an output's extreme value that make it a measured limit.
PLATEAU = 5

#: The values of ``output_limits`` besides given limits.
MEASURED = "measured"


def _longest_run(values: np.ndarray, level: float) -> int:
    """The longest run of consecutive samples of ``values`` equal to ``level``."""
    at = np.concatenate([[0], (values == level).astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(at))
    return int(np.max(edges[1::2] - edges[::2])) if len(edges) else 0


def measured_limits(y: list[Float2D], plateau: int = PLATEAU) -> Float2D:
    """The limits the training outputs show: each output's smallest and largest value over
    the experiments where some experiment holds it for ``plateau`` samples or more.

    Parameters
    ----------
    y : list of ndarrays of shape (N_e, m)
    plateau : int, default PLATEAU

    Returns
    -------
    ndarray of shape (2, m)
        Row 0 the lower limits, row 1 the upper ones; -inf and inf where none.
    """
    stacked = np.vstack(y)
    limits = np.vstack([np.full(stacked.shape[1], -np.inf),
                        np.full(stacked.shape[1], np.inf)])
    for j in range(stacked.shape[1]):
        for row, level in enumerate((stacked[:, j].min(), stacked[:, j].max())):
            if max(_longest_run(ye[:, j], level) for ye in y) >= plateau:
                limits[row, j] = level
    return limits


def resolve_limits(option, y: list[Float2D]) -> Float2D:
    """The limits of an estimator's ``output_limits`` on its training outputs ``y``:
    None (none), ``"measured"`` (`measured_limits`) or given (2, m) values, NaN or ±inf
    where an output has none.

    Raises
    ------
    ValueError
        Given limits of another shape than (2, m), or a lower limit above the upper one.
    """
    m = y[0].shape[1]
    if option is None:
        return np.vstack([np.full(m, -np.inf), np.full(m, np.inf)])
    if isinstance(option, str):
        return measured_limits(y)
    limits = np.array(option, dtype=float, copy=True)
    if limits.shape != (2, m):
        raise ValueError(f"output_limits must be 'measured', None or an array of shape (2, "
                         f"{m}) (lower limits, then upper ones, NaN where none), got shape "
                         f"{limits.shape}")
    limits[0][np.isnan(limits[0])] = -np.inf
    limits[1][np.isnan(limits[1])] = np.inf
    wrong = np.flatnonzero(limits[0] > limits[1])
    if len(wrong):
        j = int(wrong[0])
        raise ValueError(f"output_limits: y{j + 1}'s lower limit {limits[0, j]:g} is above its "
                         f"upper limit {limits[1, j]:g}")
    return limits


def has_limits(limits: Float2D | None) -> bool:
    """Whether any output of ``limits`` (2, m) has a finite limit."""
    return limits is not None and bool(np.any(np.isfinite(limits)))


#: What `describe` puts before an output's limits in a structure's description.
LIMITED = ", limited to "


def bounds(limits: Float2D, j: int, name: str) -> str:
    """Output j's limits as an inequality (``"y1 ≤ 10"``, ``"0 ≤ y1 ≤ 10"``), empty
    without any."""
    lo, hi = limits[:, j]
    if not (np.isfinite(lo) or np.isfinite(hi)):
        return ""
    text = f"{lo:.4g} ≤ {name}" if np.isfinite(lo) else name
    return f"{text} ≤ {hi:.4g}" if np.isfinite(hi) else text


def all_bounds(limits: Float2D | None, names: list[str], outputs=None) -> str:
    """The limits of the outputs ``outputs`` (default: all) that have any, as `bounds`
    names them (``names[j]`` for output j), joined: ``"y1 ≤ 10, 0 ≤ y2"``; empty without
    any (or without ``limits``)."""
    if limits is None:
        return ""
    chosen = range(limits.shape[1]) if outputs is None else outputs
    return ", ".join(filter(None, (bounds(limits, j, names[j]) for j in chosen)))


def describe(limits: Float2D, j: int, name: str) -> str:
    """Output j's limits for its structure's description (``", limited to y1 ≤ 10"``),
    empty without any."""
    text = bounds(limits, j, name)
    return LIMITED + text if text else ""
