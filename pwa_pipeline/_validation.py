"""Input checks shared by every estimator: shapes, finiteness, experiment lists."""

from collections.abc import Sequence

import numpy as np

from ._typing import Float2D, Signals


def as_signal(x: object, name: str) -> Float2D:
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {type(x).__name__}: {exc}") from None
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be 2-D with shape (n_samples, n_channels), got shape {arr.shape}"
        )
    if arr.shape[1] == 0:
        raise ValueError(f"{name} has no channels (shape {arr.shape})")
    bad = ~np.isfinite(arr)
    if bad.any():
        rows, cols = np.nonzero(bad)
        kind = "NaN" if np.isnan(arr[rows[0], cols[0]]) else "inf"
        raise ValueError(
            f"{name} contains {bad.sum()} non-finite value(s) (first: {kind} at sample "
            f"{rows[0]}, channel {cols[0]}); remove or interpolate them before fitting"
        )
    return arr


def _is_experiment_list(x: object) -> bool:
    if isinstance(x, np.ndarray):
        return False
    if isinstance(x, Sequence) and len(x) > 0:
        return all(np.ndim(e) == 2 or isinstance(e, np.ndarray) for e in x)
    return False


def as_experiments(
    u: Signals, y: Signals, *, u_name: str = "u", y_name: str = "y"
) -> list[tuple[Float2D, Float2D]]:
    """Check one or several experiments and return them as a list of ``(u, y)`` pairs.

    Parameters
    ----------
    u, y : array-like of shape (N, r) and (N, m), or lists of such arrays
        One experiment, or several separate experiments (same r and m in each).
        1-D arrays are read as a single channel.

    Returns
    -------
    list of (ndarray, ndarray)
        Float copies of each experiment's input and output.

    Raises
    ------
    ValueError
        On NaN or inf, mismatched lengths, wrong dimensions, or inconsistent widths.
    """
    u_list = list(u) if _is_experiment_list(u) else [u]
    y_list = list(y) if _is_experiment_list(y) else [y]
    if len(u_list) != len(y_list):
        raise ValueError(
            f"{u_name} has {len(u_list)} experiment(s) but {y_name} has {len(y_list)}"
        )
    pairs = []
    for i, (ue, ye) in enumerate(zip(u_list, y_list, strict=True)):
        tag = f" (experiment {i})" if len(u_list) > 1 else ""
        ua = as_signal(ue, u_name + tag)
        ya = as_signal(ye, y_name + tag)
        if ua.shape[0] != ya.shape[0]:
            raise ValueError(
                f"{u_name} and {y_name}{tag} have different lengths: "
                f"{ua.shape[0]} and {ya.shape[0]} samples"
            )
        pairs.append((ua, ya))
    r, m = pairs[0][0].shape[1], pairs[0][1].shape[1]
    for i, (ua, ya) in enumerate(pairs):
        if ua.shape[1] != r or ya.shape[1] != m:
            raise ValueError(
                f"experiment {i} has {ua.shape[1]} inputs and {ya.shape[1]} outputs, "
                f"experiment 0 has {r} and {m}"
            )
    return pairs


def check_width(arr: Float2D, expected: int, name: str, what: str) -> None:
    """Raise a ValueError when ``arr`` does not have ``expected`` columns."""
    if arr.shape[1] != expected:
        raise ValueError(
            f"{name} has {arr.shape[1]} {what} but the model was fitted with {expected}"
        )
