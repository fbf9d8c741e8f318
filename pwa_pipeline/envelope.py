"""The data envelope: where a fitted ARX-structured model has seen data.

A model identified from data is known only where its regressor φ(k) (eq. 2–3) went during
training; elsewhere it extrapolates, and a PWA model's regions, drawn through the training
regressors, say nothing there. The **data envelope** is the box in which each entry of φ
(the constant left out) lies within its channel's training range, the smallest and largest
value of that output or input over the training experiments (``signal_range_``, recorded by
``fit``; every lag of a channel shares it), widened on either side by `PADDING` of the
span (of the channel's magnitude, at least 1, when the span is zero, so that a constant
channel still has a box around its value).

A box, not the convex hull of the training regressors: it is what the state-space form
bounds its regions with (`pwa_pipeline.control`, whose envelope over z = [x; u] is this
box over x = φ without the constant, with the inputs' own ranges appended for u(k)), it is
cheap to test per sample, and it names the channel that left it. It is a necessary
condition only: a regressor inside the box may still combine its entries in a way the
training data never did.

This module is the one place the box is computed; the estimators
(`outside_envelope`), the evaluation protocol and
the state-space conversion all call it.
"""

import numpy as np

from ._typing import Float2D

#: Widening of the envelope beyond the training range, as a share of each channel's span.
PADDING = 0.05

#: A value within this share of the box's width beyond a wall counts as inside (a training
#: value on the wall, or one off by rounding, is inside).
SLACK = 1e-9


def check_padding(padding: object) -> float:
    """``padding`` as a float if it is a finite share ≥ 0, else a ValueError."""
    if isinstance(padding, bool) or not isinstance(padding, int | float | np.floating | np.integer) \
            or not np.isfinite(padding) or padding < 0:
        raise ValueError(f"padding must be a finite share of each span, at least 0; got "
                         f"{padding!r}")
    return float(padding)


def channel_bounds(signal_range: Float2D, padding: float = PADDING
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each channel's training range widened by ``padding`` of its span on either side.

    Parameters
    ----------
    signal_range : array-like of shape (2, m + r)
        Row 0 the minima, row 1 the maxima of each output, then each input
        (`training_range`).
    padding : float, default PADDING
        Share of each span added on either side; of max(|min|, |max|, 1) for a channel whose
        span is zero.

    Returns
    -------
    lower, upper : ndarrays of shape (m + r,)

    Raises
    ------
    ValueError
        If ``signal_range`` is not of shape (2, channels), holds non-finite values or a
        minimum above its maximum, or ``padding`` is negative or not finite.
    """
    padding = check_padding(padding)
    rng = np.asarray(signal_range, dtype=float)
    if rng.ndim != 2 or rng.shape[0] != 2:
        raise ValueError(f"signal_range must have shape (2, channels), got {rng.shape}")
    if not np.all(np.isfinite(rng)) or np.any(rng[0] > rng[1]):
        raise ValueError("signal_range must hold finite minima (row 0) no larger than the "
                         "maxima (row 1)")
    lo, hi = rng
    span = hi - lo
    pad = padding * np.where(span > 0, span, np.maximum(np.maximum(abs(lo), abs(hi)), 1.0))
    return lo - pad, hi + pad


def regressor_channels(m: int, r: int, output_lags: int, input_lags: int) -> list[int]:
    """The channel (outputs 0 … m−1, then inputs m … m+r−1) of each entry of φ without the
    constant, in eq. (3)'s order: per output its lags, then per input its lags."""
    return ([p for p in range(m) for _ in range(output_lags)]
            + [m + q for q in range(r) for _ in range(input_lags)])


def regressor_bounds(signal_range: Float2D, m: int, r: int, output_lags: int,
                     input_lags: int, padding: float = PADDING
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The data envelope over φ(k) without the constant: each entry bounded by its channel's
    `channel_bounds`.

    Parameters
    ----------
    signal_range : array-like of shape (2, m + r)
    m, r : int
        Outputs and inputs.
    output_lags, input_lags : int
        Lags of each output (na, or na + 1 in the velocity form) and of each input (nb).
    padding : float, default PADDING

    Returns
    -------
    lower, upper : ndarrays of shape (m·output_lags + r·input_lags,)
    """
    lo, hi = channel_bounds(signal_range, padding)
    if lo.size != m + r:
        raise ValueError(f"signal_range has {lo.size} channel(s); the model has {m} output(s) "
                         f"and {r} input(s)")
    channel = regressor_channels(m, r, output_lags, input_lags)
    return lo[channel], hi[channel]


def outside_box(values: Float2D, lower: np.ndarray, upper: np.ndarray,
                slack: float = SLACK) -> np.ndarray:
    """Whether each row of ``values`` leaves the box lower ≤ v ≤ upper.

    Parameters
    ----------
    values : ndarray of shape (N, p)
    lower, upper : ndarrays of shape (p,)
    slack : float, default SLACK
        A value beyond a wall by at most ``slack`` times the box's width there is inside.

    Returns
    -------
    ndarray of bool, shape (N,)
        True where some entry is outside, or not finite (a diverged simulation's NaN).
    """
    values = np.asarray(values, dtype=float)
    margin = slack * (upper - lower)
    with np.errstate(invalid="ignore"):
        inside = (values >= lower - margin) & (values <= upper + margin)
    return ~np.all(inside, axis=1)


def training_range(experiments: list[tuple[Float2D, Float2D]]) -> Float2D:
    """Smallest and largest value of each output, then each input, over the experiments.

    Parameters
    ----------
    experiments : list of (u, y)
        As `as_experiments` returns them.

    Returns
    -------
    ndarray of shape (2, m + r)
        Row 0 the minima, row 1 the maxima: the estimators keep it as ``signal_range_``,
        the data envelope of their state-space form (`pwa_pipeline.control`).
    """
    joined = np.vstack([np.hstack([y, u]) for u, y in experiments])
    return np.vstack([joined.min(axis=0), joined.max(axis=0)])
