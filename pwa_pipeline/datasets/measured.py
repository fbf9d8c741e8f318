"""Two measured nonlinear benchmarks with their official splits and scoring conventions: the
cascaded tanks (Schoukens et al. 2016) and the electro-mechanical positioning system, EMPS
(Janot et al. 2019). Their files are read from a configured path and never part of this
repository.

Each benchmark's own figure of merit is a free-run RMSE in the output's units over a stated
window of the test record, its first samples given to set the initial state
(`Dataset.convention`, scored by
`single_run_scores`). Published figures use these
conventions; this project's NRMSE (eq. 21) is reported beside them, never mixed with them.
"""

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..scoring.conventions import Convention
from .dataset import Dataset

#: The cascaded tanks' figure of merit: free-run RMSE in volts of the test record from its
#: 6th sample, its first 5 measured outputs setting the initial state (the
#: ``nonlinear_benchmarks`` loader's window on GitHub; its 1.0.1 release skips 50, the
#: benchmark's PDF none).
TANKS_CONVENTION = Convention("rmse_V_from_5", "none", restart=False, warmup=5, unit="V")
#: EMPS' figure of merit: free-run RMSE in millimetres of the motor position ``qm[20:]`` of
#: the test record (``DATA_EMPS_PULSES``), its first 20 samples setting the initial state.
EMPS_CONVENTION = Convention("rmse_mm_from_20", "none", restart=False, warmup=20, unit="mm",
                             scale=1000.0)


@dataclass(frozen=True)
class MeasuredSource:
    """Where a measured benchmark's files are and where they come from.

    Attributes
    ----------
    name : str
        The data set's name (a pipeline partition's ``dataset``).
    env : str
        The environment variable that points to the folder holding the files.
    folder : str
        The folder's name under ``../shared/data`` beside the project, the default.
    files : tuple of str
        The official files read.
    download : str
        The official download, named in the error when a file is missing.
    convention : Convention
        The benchmark's figure of merit (`Dataset.convention`).
    """

    name: str
    env: str
    folder: str
    files: tuple[str, ...]
    download: str
    convention: Convention

    def path(self) -> Path:
        """``$<env>`` if set, else ``../shared/data/<folder>`` beside the project."""
        env = os.environ.get(self.env)
        if env:
            return Path(env)
        return Path(__file__).resolve().parents[3] / "shared" / "data" / self.folder

    def missing(self, path: str | os.PathLike | None = None) -> list[Path]:
        """The official files absent from ``path`` (default
        [`path`][pwa_pipeline.datasets.measured.MeasuredSource.path])."""
        base = Path(path) if path is not None else self.path()
        return [base / f for f in self.files if not (base / f).is_file()]

    def require(self, path: str | os.PathLike | None = None) -> Path:
        """The folder holding every official file.

        Raises
        ------
        FileNotFoundError
            Naming the files missing, the official download and the variable to set.
        """
        base = Path(path) if path is not None else self.path()
        missing = self.missing(base)
        if missing:
            raise FileNotFoundError(
                f"{self.name} data not found: {', '.join(str(m.resolve()) for m in missing)} "
                f"missing. Download {self.download}, and pass its folder or set {self.env} "
                f"to it")
        return base


TANKS = MeasuredSource(
    "cascaded_tanks", "PWA_TANKS_DATA", "cascaded-tanks", ("dataBenchmark.csv",),
    "CascadedTanksFiles.zip from nonlinearbenchmark.org ('Cascaded tanks'; also on "
    "4TU.ResearchData), which holds CascadedTanksFiles/dataBenchmark.csv", TANKS_CONVENTION)
EMPS = MeasuredSource(
    "emps", "PWA_EMPS_DATA", "emps", ("DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"),
    "EMPS.zip from nonlinearbenchmark.org ('Electro-Mechanical Positioning System'), which "
    "holds DATA_EMPS.mat and DATA_EMPS_PULSES.mat", EMPS_CONVENTION)

TANKS_LENGTH = 1024
TANKS_COLUMNS = ("uEst", "yEst", "uVal", "yVal", "Ts")
EMPS_VARIABLES = ("vir", "qm", "t")


def load_cascaded_tanks(path: str | os.PathLike | None = None) -> Dataset:
    """The cascaded tanks benchmark: pump voltage ``u`` [V] → lower-tank level ``y`` [V].

    Estimation record ``uEst, yEst`` for training and test record ``uVal, yVal`` held out,
    1024 samples each, 4 s apart; both start from the same unknown state. The test record is
    for scoring only (`TANKS_CONVENTION`).

    Parameters
    ----------
    path : path-like, optional
        The folder holding ``dataBenchmark.csv``. Default: ``$PWA_TANKS_DATA``, else
        ``../shared/data/cascaded-tanks`` beside the project.

    Raises
    ------
    FileNotFoundError
        Naming the file and the official download.
    ValueError
        When the file is not a CSV table, lacks a column, or a record is not 1024 finite
        samples long (naming the file and the column).

    References
    ----------
    M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noël, "Cascaded tanks benchmark combining
    soft and hard nonlinearities", Workshop on Nonlinear System Identification Benchmarks,
    2016.
    """
    file = TANKS.require(path) / TANKS.files[0]
    try:
        table = pd.read_csv(file)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise ValueError(f"{file}: not a CSV table that can be read ({exc}); the "
                         f"benchmark's file is a CSV with columns {list(TANKS_COLUMNS)} "
                         f"({TANKS.download})") from exc
    missing = [c for c in TANKS_COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(f"{file}: column(s) {missing} missing; the benchmark's file has "
                         f"{list(TANKS_COLUMNS)}")
    columns = {}
    for c in TANKS_COLUMNS[:4]:
        x = pd.to_numeric(table[c], errors="coerce").to_numpy(float)
        if len(x) != TANKS_LENGTH or not np.isfinite(x).all():
            raise ValueError(f"{file}: column {c!r} should hold {TANKS_LENGTH} numbers, it "
                             f"holds {int(np.isfinite(x).sum())} of {len(x)} rows")
        columns[c] = x[:, None]
    return Dataset("cascaded_tanks", [columns["uEst"]], [columns["yEst"]], [columns["uVal"]],
                   [columns["yVal"]], u_names=["u"], y_names=["y"],
                   units={"u": "V", "y": "V"}, sample_time=float(table["Ts"].iloc[0]),
                   convention=TANKS.convention)


def _emps_record(file: Path) -> tuple[np.ndarray, np.ndarray, float]:
    from scipy.io import loadmat

    try:
        mat = loadmat(file)
    except NotImplementedError as exc:  # scipy reads MATLAB v4–v7.2, not v7.3's HDF5
        raise ValueError(f"{file}: a MATLAB file of a version scipy does not read ({exc}); "
                         f"the benchmark's files are MATLAB v5 ({EMPS.download})") from exc
    except (ValueError, TypeError, IndexError, OSError) as exc:
        raise ValueError(f"{file}: not a MATLAB file that can be read ({exc}); the "
                         f"benchmark's files are MATLAB v5 ({EMPS.download})") from exc
    missing = [v for v in EMPS_VARIABLES if v not in mat]
    if missing:
        raise ValueError(f"{file}: variable(s) {missing} missing; the benchmark's files hold "
                         f"{list(EMPS_VARIABLES)}")
    arrays = {v: np.asarray(mat[v], dtype=float).reshape(-1) for v in EMPS_VARIABLES}
    n = len(arrays["t"])
    for v, x in arrays.items():
        if len(x) != n or not np.isfinite(x).all() or n < 100:
            raise ValueError(f"{file}: variable {v!r} should hold {n} finite samples like 't' "
                             f"(at least 100), it holds {int(np.isfinite(x).sum())} of "
                             f"{len(x)}")
    return arrays["vir"][:, None], arrays["qm"][:, None], float(np.median(np.diff(arrays["t"])))


def load_emps(path: str | os.PathLike | None = None) -> Dataset:
    """The EMPS benchmark: the controller's output ``vir`` [V] → motor position ``qm`` [m].

    ``DATA_EMPS.mat`` for training and ``DATA_EMPS_PULSES.mat`` (the same reference with force
    pulses on the load) held out, 24,841 samples each at 1 kHz, measured in closed loop. The
    test record is for scoring only (`EMPS_CONVENTION`).

    Parameters
    ----------
    path : path-like, optional
        The folder holding both files. Default: ``$PWA_EMPS_DATA``, else
        ``../shared/data/emps`` beside the project.

    Raises
    ------
    FileNotFoundError
        Naming the files and the official download.
    ValueError
        When a file is not a MATLAB v5 file scipy reads (a v7.3 file included), lacks a
        variable, or its variables differ in length (naming the file and the variable).

    References
    ----------
    A. Janot, M. Gautier, M. Brunot, "Data Set and Reference Models of EMPS", Workshop on
    Nonlinear System Identification Benchmarks, 2019.
    """
    base = EMPS.require(path)
    u_train, y_train, ts = _emps_record(base / EMPS.files[0])
    u_test, y_test, _ = _emps_record(base / EMPS.files[1])
    return Dataset("emps", [u_train], [y_train], [u_test], [y_test], u_names=["vir"],
                   y_names=["qm"], units={"vir": "V", "qm": "m"}, sample_time=ts,
                   convention=EMPS.convention)


#: The measured benchmarks by name: their source and loader.
MEASURED: dict[str, tuple[MeasuredSource, Callable[..., Dataset]]] = {
    TANKS.name: (TANKS, load_cascaded_tanks), EMPS.name: (EMPS, load_emps)}
