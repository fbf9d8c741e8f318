"""Data sets: the paper's simulated 2×2 PWA system, the KUKA KR300 robot, and user tables."""

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._typing import Float2D

#: Sub-model matrices of eq. (11), as θ_i of shape (d, m) = (4, 2), for modes λ = 1 … 4.
HURE_VASAK_THETAS = np.array(
    [
        [[0.9, 0.0, 0.1, 0.0], [0.0, 0.6, 0.0, 0.4]],
        [[0.7, 0.0, 0.3, 0.0], [0.15, 0.6, 0.0, 0.4]],
        [[0.7, -0.2, 0.3, 0.0], [0.15, 0.8, 0.0, 0.2]],
        [[0.9, -0.2, 0.1, 0.0], [0.0, 0.8, 0.0, 0.2]],
    ]
).transpose(0, 2, 1)

KUKA_SEGMENT = 606
KUKA_DOWNLOAD = (
    "the official archive Robot_Identification_Benchmark_Without_Raw_Data.rar "
    "(DOI 10.26204/DATA/5, 'Industrial robot' on nonlinearbenchmark.org), which holds "
    "forward_identification_without_raw_data.mat"
)
KUKA_FILES = ("forward_identification_reconstructed.mat", "forward_identification_without_raw_data.mat")


@dataclass(frozen=True)
class SimulatedPWA:
    """A simulated PWARX data set with its ground truth.

    Attributes
    ----------
    u : ndarray of shape (N, r)
    y : ndarray of shape (N, m)
        Measured (noisy) outputs.
    y_clean : ndarray of shape (N, m)
    modes : ndarray of shape (N,)
        True sub-model (0-based) that produced y(k).
    thetas : ndarray of shape (s, d, m)
        True parameter matrices.
    snr_db : float or None
    """

    u: Float2D
    y: Float2D
    y_clean: Float2D
    modes: np.ndarray
    thetas: np.ndarray
    snr_db: float | None
    u_names: list[str] = field(default_factory=lambda: ["u1", "u2"])
    y_names: list[str] = field(default_factory=lambda: ["y1", "y2"])


def hure_vasak_mode(y_prev: Float2D) -> np.ndarray:
    """Mode λ − 1 of eq. (12) from y(k−1): quadrants of (y1, y2) around (0.5, 0.5)."""
    hi1, hi2 = y_prev[..., 0] > 0.5, y_prev[..., 1] > 0.5
    return np.select([hi1 & hi2, ~hi1 & hi2, ~hi1 & ~hi2], [0, 1, 2], default=3)


def add_output_noise(y_clean: Float2D, snr_db: float, rng: np.random.Generator) -> Float2D:
    """Gaussian noise scaled so that eq. (14) holds exactly for every output."""
    e = rng.standard_normal(y_clean.shape)
    gain = np.sqrt((y_clean**2).sum(axis=0) / (10 ** (snr_db / 10) * (e**2).sum(axis=0)))
    return e * gain


def make_hure_vasak(
    n_samples: int = 4000, snr_db: float | None = 30.0, seed: int = 0, burn_in: int = 100
) -> SimulatedPWA:
    """The 2-input, 2-output, 4-mode PWA system of the paper's section 5 (eq. 11–14).

    u(k) is white and uniform in the box [−4, 6] × [−2, 4]; y(k) = θ_λᵀ [y(k−1); u(k−1)] with
    λ from eq. (12); the measured output is y + e with e Gaussian at ``snr_db`` per output as
    eq. (14) defines it (``None``: noise-free). The first ``burn_in`` simulated samples are
    dropped so that the record starts in steady operation.

    Parameters
    ----------
    n_samples : int, default 4000
    snr_db : float or None, default 30
    seed : int, default 0
    burn_in : int, default 100
    """
    if n_samples < 2:
        raise ValueError(f"n_samples must be at least 2, got {n_samples}")
    rng = np.random.default_rng(seed)
    total = n_samples + burn_in
    u = np.column_stack([rng.uniform(-4, 6, total), rng.uniform(-2, 4, total)])
    y = np.zeros((total, 2))
    modes = np.zeros(total, dtype=int)
    for k in range(1, total):
        modes[k] = hure_vasak_mode(y[k - 1])
        y[k] = np.concatenate([y[k - 1], u[k - 1]]) @ HURE_VASAK_THETAS[modes[k]]
    u, y, modes = u[burn_in:], y[burn_in:], modes[burn_in:]
    noise = np.zeros_like(y) if snr_db is None else add_output_noise(y, snr_db, rng)
    return SimulatedPWA(u=u, y=y + noise, y_clean=y, modes=modes,
                        thetas=HURE_VASAK_THETAS.copy(), snr_db=snr_db)


@dataclass(frozen=True)
class RobotData:
    """KUKA KR300 forward identification data as separate 606-sample experiments.

    Attributes
    ----------
    u_train, y_train : lists of ndarrays of shape (≤606, 6)
        Motor torques (Nm) and joint positions (degrees) of the training record.
    u_test, y_test : lists of ndarrays of shape (606, 6)
        The held-out test record.
    path : Path
    """

    u_train: list[Float2D]
    y_train: list[Float2D]
    u_test: list[Float2D]
    y_test: list[Float2D]
    path: Path
    u_names: list[str] = field(default_factory=lambda: [f"tau{i}" for i in range(1, 7)])
    y_names: list[str] = field(default_factory=lambda: [f"q{i}" for i in range(1, 7)])


def default_kuka_path() -> Path:
    """``$PWA_KUKA_DATA`` if set, else ``../shared/data/kuka-kr300`` beside the project."""
    env = os.environ.get("PWA_KUKA_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / "shared" / "data" / "kuka-kr300"


def _split(x: Float2D, length: int) -> list[Float2D]:
    return [x[i : i + length] for i in range(0, x.shape[0], length)]


def load_kuka(path: str | os.PathLike | None = None, segment: int = KUKA_SEGMENT) -> RobotData:
    """Load the KUKA KR300 forward identification benchmark, cut into experiments.

    Parameters
    ----------
    path : path-like, optional
        The ``.mat`` file or the folder holding it. Default: :func:`default_kuka_path`.
    segment : int, default 606
        Experiment length; regressors and simulations must not span two experiments.

    Raises
    ------
    FileNotFoundError
        Naming the path searched and where the official file can be downloaded.
    ValueError
        If the file lacks the benchmark's variables.
    """
    from scipy.io import loadmat

    base = Path(path) if path is not None else default_kuka_path()
    candidates = [base] if base.suffix == ".mat" else [base / f for f in KUKA_FILES]
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        raise FileNotFoundError(
            f"KUKA robot data not found at {base.resolve()} (looked for "
            f"{', '.join(str(c.name) for c in candidates)}). Download {KUKA_DOWNLOAD}, and "
            f"pass its path or set PWA_KUKA_DATA to it"
        )
    mat = loadmat(found)
    missing = [k for k in ("u_train", "y_train", "u_test", "y_test") if k not in mat]
    if missing:
        raise ValueError(f"{found} lacks the benchmark variable(s) {', '.join(missing)}")
    arrays = {k: np.asarray(mat[k], dtype=float).T for k in ("u_train", "y_train", "u_test", "y_test")}
    return RobotData(
        u_train=_split(arrays["u_train"], segment),
        y_train=_split(arrays["y_train"], segment),
        u_test=_split(arrays["u_test"], segment),
        y_test=_split(arrays["y_test"], segment),
        path=found,
    )


def load_table(
    path: str | os.PathLike,
    u_columns: list[str],
    y_columns: list[str],
    experiment_column: str | None = None,
) -> tuple[list[Float2D], list[Float2D]]:
    """Read user data from CSV or Parquet with named input and output columns.

    Parameters
    ----------
    path : path-like
        A ``.csv`` or ``.parquet`` file.
    u_columns, y_columns : list of str
        Column names of the inputs and outputs.
    experiment_column : str, optional
        Column identifying separate experiments (rows kept in file order within each).

    Returns
    -------
    u, y : lists of ndarrays, one per experiment

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, unknown format, missing columns, or non-numeric values.
    """
    import pandas as pd

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"data file not found: {p.resolve()}")
    readers = {".csv": pd.read_csv, ".parquet": pd.read_parquet}
    if p.suffix.lower() not in readers:
        raise ValueError(f"unsupported file type {p.suffix!r} for {p}: use .csv or .parquet")
    df = readers[p.suffix.lower()](p)
    wanted = list(u_columns) + list(y_columns) + ([experiment_column] if experiment_column else [])
    missing = [c for c in wanted if c not in df.columns]
    if missing:
        raise ValueError(f"{p.name} has no column(s) {missing}; it has {list(df.columns)}")
    groups = [df] if experiment_column is None else [g for _, g in df.groupby(experiment_column, sort=False)]
    try:
        u = [g[list(u_columns)].to_numpy(dtype=float) for g in groups]
        y = [g[list(y_columns)].to_numpy(dtype=float) for g in groups]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{p.name}: non-numeric value in the u/y columns ({exc})") from None
    return u, y


@dataclass(frozen=True)
class Dataset:
    """Training and held-out experiments of one data set, with channel names."""

    name: str
    u_train: list[Float2D]
    y_train: list[Float2D]
    u_test: list[Float2D]
    y_test: list[Float2D]
    u_names: list[str]
    y_names: list[str]

    @property
    def n_train(self) -> int:
        """Training samples."""
        return sum(len(u) for u in self.u_train)

    @property
    def n_test(self) -> int:
        """Held-out samples."""
        return sum(len(u) for u in self.u_test)


DATASETS = ("hure_vasak", "kuka_robot")


def load_dataset(name: str, kuka_path: str | os.PathLike | None = None, seed: int = 0) -> Dataset:
    """A named data set with its training and held-out parts.

    ``hure_vasak``: the section 5 system at 30 dB, N = 4000, ``seed`` for training and a fresh
    record (seed + 1000) for validation. ``kuka_robot``: :func:`load_kuka` (train / test).
    """
    if name == "hure_vasak":
        train, test = make_hure_vasak(seed=seed), make_hure_vasak(seed=seed + 1000)
        return Dataset(name, [train.u], [train.y], [test.u], [test.y], train.u_names,
                       train.y_names)
    if name == "kuka_robot":
        r = load_kuka(kuka_path)
        return Dataset(name, r.u_train, r.y_train, r.u_test, r.y_test, r.u_names, r.y_names)
    raise ValueError(f"unknown data set {name!r}; known: {list(DATASETS)}")
