"""Input checks shared by every estimator: shapes, finiteness, experiment lists."""

import re
from collections.abc import Sequence

import numpy as np

from ._typing import Float2D, Signals

# Magnitude limits. Fitting forms squares, products and sums of squares of signal values. With
# every |x| <= 1e150 these stay <= 1e300, a factor ~1e8 below the float64 maximum (1.8e308), so
# sums of up to ~1e8 such terms cannot overflow. With a channel's largest |x| >= 1e-150 its
# squares reach >= 1e-300, a factor ~1e8 above the smallest normal float64 (2.2e-308), so they
# neither underflow to zero nor lose precision as subnormals.
MAX_MAGNITUDE = 1e150
MIN_MAGNITUDE = 1e-150
#: More channels than this, and than samples, is taken for a transposed signal.
MAX_CHANNELS = 256
#: Names of data sets, hyper-parameter sets and assets: they become paths and partition keys.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_-]+")
#: Their longest: a name is one component of several file paths and MLflow names (with a
#: prefix and suffix each), which file systems cap at 255 bytes.
MAX_NAME_LENGTH = 64


def check_name(name: str, what: str) -> str:
    """``name`` if it matches `NAME_PATTERN` within `MAX_NAME_LENGTH`
    characters, else a ValueError naming ``what``."""
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name) \
            or len(name) > MAX_NAME_LENGTH:
        shown = name if not isinstance(name, str) or len(name) <= 80 else name[:77] + "..."
        raise ValueError(f"invalid {what} name {shown!r}: use letters, digits, '_' and '-' "
                         f"only, at most {MAX_NAME_LENGTH} characters")
    return name


def _not_numeric(x: object, name: str, exc: Exception) -> ValueError:
    return ValueError(f"{name} must be numeric, got {type(x).__name__}: {exc}")


def as_signal(x: object, name: str) -> Float2D:
    """Check one signal and return it as a float array of shape (n_samples, n_channels).

    Parameters
    ----------
    x : array-like of shape (N,) or (N, channels)
        A 1-D array is read as a single channel. A ``numpy.ma.MaskedArray`` is accepted
        only when no entry is masked.
    name : str
        The signal's name in error messages.

    Returns
    -------
    ndarray of shape (N, channels)

    Raises
    ------
    ValueError
        If ``x`` is not numeric, is complex (even with every imaginary part zero: a real
        signal is needed), is not 1-D or 2-D, has no channels, has masked entries, holds NaN
        or inf, or has a channel whose largest magnitude exceeds 1e150 or whose nonzero
        values are all below 1e-150 (float64 squares would overflow or underflow; an
        all-zero channel is accepted).
    """
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise _not_numeric(x, name, exc) from None
    if np.iscomplexobj(raw):
        raise ValueError(
            f"{name} is complex (dtype {raw.dtype}); a real signal is needed: pass its real "
            f"part, magnitude or phase explicitly"
        )
    if raw.dtype.kind in "USO" and any(isinstance(v, (str, bytes)) for v in raw.flat):
        raise ValueError(f"{name} must be numeric: it holds text (dtype {raw.dtype}); convert "
                         f"it where it is read, so that a bad cell is seen there")
    try:
        arr = raw.astype(float, copy=False)
    except (TypeError, ValueError) as exc:
        raise _not_numeric(x, name, exc) from None
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be 2-D with shape (n_samples, n_channels), got shape {arr.shape}"
        )
    if arr.shape[1] == 0:
        raise ValueError(f"{name} has no channels (shape {arr.shape})")
    if arr.shape[1] > max(arr.shape[0], MAX_CHANNELS):
        raise ValueError(
            f"{name} has shape {arr.shape}: {arr.shape[1]} channels of {arr.shape[0]} "
            f"sample(s). Signals are (n_samples, n_channels); is it transposed?")
    if np.ma.isMaskedArray(x):
        masked = np.ma.getmaskarray(x).reshape(arr.shape)
        if masked.any():
            rows, cols = np.nonzero(masked)
            raise ValueError(
                f"{name} has {masked.sum()} masked value(s) (first at sample {rows[0]}, "
                f"channel {cols[0]}); a masked sample cannot be fitted: remove or interpolate "
                f"them and pass an unmasked array"
            )
    bad = ~np.isfinite(arr)
    if bad.any():
        rows, cols = np.nonzero(bad)
        kind = "NaN" if np.isnan(arr[rows[0], cols[0]]) else "inf"
        raise ValueError(
            f"{name} contains {bad.sum()} non-finite value(s) (first: {kind} at sample "
            f"{rows[0]}, channel {cols[0]}); remove or interpolate them before fitting"
        )
    peak = np.abs(arr).max(axis=0, initial=0.0)
    for j, top in enumerate(peak):
        if top > MAX_MAGNITUDE:
            raise ValueError(
                f"{name} channel {j} reaches magnitude {top:.3g}, above {MAX_MAGNITUDE:.0e}: its "
                f"float64 squares would overflow; rescale the data (e.g. to engineering units)"
            )
        if 0 < top < MIN_MAGNITUDE:
            raise ValueError(
                f"{name} channel {j} has no value above {MIN_MAGNITUDE:.0e} in magnitude "
                f"(largest {top:.3g}): its float64 squares would underflow; rescale the data "
                f"(e.g. to engineering units)"
            )
    return arr


def check_n_init(n_init: object, n_samples: int) -> None:
    """Refuse a warm-up ``n_init`` that is not a whole number from 0 to below ``n_samples``
    (a longer one would return the measured outputs as the prediction)."""
    if n_init is None:
        return
    if isinstance(n_init, bool) or not isinstance(n_init, (int, np.integer)):
        raise ValueError(f"n_init must be a whole number of samples, got {n_init!r}")
    if not 0 <= n_init < n_samples:
        raise ValueError(f"n_init = {n_init} must be at least 0 and below the {n_samples} "
                         f"samples given: those rows are returned as measured, so nothing "
                         f"would be predicted")


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
        On NaN or inf, mismatched lengths, an experiment without samples, wrong dimensions,
        or inconsistent widths.
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
        if ua.shape[0] == 0:
            raise ValueError(f"{u_name} and {y_name}{tag} have no samples (shapes {ua.shape} "
                             f"and {ya.shape}): an experiment needs at least one")
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


def warmup_pairs(u: Signals, y_init: Signals, n_inputs: int, n_outputs: int,
                 n_initial: int) -> list[tuple[Float2D, Float2D]]:
    """The experiments of a free run, ``(u, y_init)`` per experiment, checked: as many of
    each, the widths the model was fitted with, and a warm-up of at least ``n_initial`` rows
    (max(output lags, nb)) and at most u's length.

    Raises
    ------
    ValueError
        Naming what does not fit (and the experiment, for a warm-up longer than its u).
    """
    u_list = list(u) if _is_experiment_list(u) else [u]
    y_list = list(y_init) if _is_experiment_list(y_init) else [y_init]
    if len(u_list) != len(y_list):
        raise ValueError(f"u has {len(u_list)} experiment(s) but y_init has {len(y_list)}")
    pairs = []
    for i, (ue, ye) in enumerate(zip(u_list, y_list, strict=True)):
        ue, ye = as_signal(ue, "u"), as_signal(ye, "y_init")
        check_width(ue, n_inputs, "u", "input(s)")
        check_width(ye, n_outputs, "y_init", "output(s)")
        if ye.shape[0] < n_initial:
            raise ValueError(
                f"warm-up too short: y_init has {ye.shape[0]} row(s), the model needs at "
                f"least max(output lags, nb) = {n_initial}")
        if ye.shape[0] > ue.shape[0]:
            raise ValueError(
                f"y_init has {ye.shape[0]} rows but u only {ue.shape[0]} (experiment {i})")
        pairs.append((ue, ye))
    return pairs
