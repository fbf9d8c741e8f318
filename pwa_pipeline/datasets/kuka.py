"""The KUKA KR300 forward-identification benchmark (the paper's section 6), read from a
configured path; the data are never part of this repository."""

import os
from pathlib import Path

import numpy as np

from .._typing import Float2D
from .dataset import Dataset

KUKA_SEGMENT = 606
KUKA_DOWNLOAD = (
    "the official archive Robot_Identification_Benchmark_Without_Raw_Data.rar "
    "(DOI 10.26204/DATA/5, 'Industrial robot' on nonlinearbenchmark.org), which holds "
    "forward_identification_without_raw_data.mat"
)
KUKA_FILES = ("forward_identification_reconstructed.mat", "forward_identification_without_raw_data.mat")
KUKA_VARIABLES = ("u_train", "y_train", "u_test", "y_test")
KUKA_CHANNELS = 6
#: Units of the benchmark's channels (its documentation): joint positions in degrees, motor
#: torques in newton metres.
KUKA_UNITS = {**{f"q{i}": "deg" for i in range(1, KUKA_CHANNELS + 1)},
              **{f"tau{i}": "N·m" for i in range(1, KUKA_CHANNELS + 1)}}


def default_kuka_path() -> Path:
    """``$PWA_KUKA_DATA`` if set, else ``../shared/data/kuka-kr300`` beside the project."""
    env = os.environ.get("PWA_KUKA_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3] / "shared" / "data" / "kuka-kr300"


def _samples_by_channels(x: object, variable: str, found: Path) -> Float2D:
    """``x`` as (samples, 6), whether stored channels × samples (as documented) or transposed."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 2 and arr.shape[0] == KUKA_CHANNELS:
        return arr.T
    if arr.ndim == 2 and arr.shape[1] == KUKA_CHANNELS:
        return arr
    raise ValueError(
        f"{found}: variable {variable!r} has shape {arr.shape}; expected {KUKA_CHANNELS} "
        f"channels × samples ({KUKA_CHANNELS}, N) or samples × channels (N, {KUKA_CHANNELS})"
    )


def _split(x: Float2D, length: int) -> list[Float2D]:
    return [x[i : i + length] for i in range(0, x.shape[0], length)]


def _candidates(base: Path) -> list[Path]:
    """The files that may hold the benchmark: ``base`` itself if it is a ``.mat`` file, else
    the `KUKA_FILES` inside it."""
    return [base] if base.suffix == ".mat" else [base / f for f in KUKA_FILES]


def find_kuka(path: str | os.PathLike | None = None) -> Path | None:
    """The benchmark's ``.mat`` file at ``path`` (default
    [`default_kuka_path`][pwa_pipeline.datasets.default_kuka_path]), or None."""
    base = Path(path) if path is not None else default_kuka_path()
    return next((c for c in _candidates(base) if c.is_file()), None)


#: Seconds between samples (10 Hz).
KUKA_SAMPLE_TIME = 0.1


def load_kuka(path: str | os.PathLike | None = None, segment: int = KUKA_SEGMENT) -> Dataset:
    """Load the KUKA KR300 forward identification benchmark, cut into experiments.

    Returns
    -------
    Dataset
        ``kuka_robot``: the training record and the held-out test record as experiments of
        ``segment`` samples (the last training one shorter), motor torques ``tau1`` …
        ``tau6`` (N·m) in and joint positions ``q1`` … ``q6`` (degrees) out.

    Parameters
    ----------
    path : path-like, optional
        The ``.mat`` file or the folder holding it. Default:
        [`default_kuka_path`][pwa_pipeline.datasets.default_kuka_path].
    segment : int, default 606
        Experiment length; regressors and simulations must not span two experiments.

    Raises
    ------
    FileNotFoundError
        Naming the path searched and where the official file can be downloaded.
    ValueError
        If the file lacks the benchmark's variables, or one of them does not have 6 channels.

    Notes
    -----
    The variables are documented as channels × samples, (6, N); a file storing them as
    samples × channels, (N, 6), is read the same way. A (6, 6) variable is read as documented.
    """
    from scipy.io import loadmat

    base = Path(path) if path is not None else default_kuka_path()
    candidates = _candidates(base)
    found = find_kuka(base)
    if found is None:
        raise FileNotFoundError(
            f"KUKA robot data not found at {base.resolve()} (looked for "
            f"{', '.join(str(c.name) for c in candidates)}). Download {KUKA_DOWNLOAD}, and "
            f"pass its path or set PWA_KUKA_DATA to it"
        )
    mat = loadmat(found)
    missing = [k for k in KUKA_VARIABLES if k not in mat]
    if missing:
        raise ValueError(f"{found} lacks the benchmark variable(s) {', '.join(missing)}")
    arrays = {k: _samples_by_channels(mat[k], k, found) for k in KUKA_VARIABLES}
    return Dataset(
        "kuka_robot", _split(arrays["u_train"], segment), _split(arrays["y_train"], segment),
        _split(arrays["u_test"], segment), _split(arrays["y_test"], segment),
        u_names=[f"tau{i}" for i in range(1, KUKA_CHANNELS + 1)],
        y_names=[f"q{i}" for i in range(1, KUKA_CHANNELS + 1)], units=dict(KUKA_UNITS),
        sample_time=KUKA_SAMPLE_TIME)
