"""Users' own data sets: a CSV or Parquet file described by name, with its columns, its
split into training and held-out experiments, and its model orders
([`UserDataset`][pwa_pipeline.datasets.UserDataset], which loads as a
[`Dataset`][pwa_pipeline.datasets.Dataset]). The pipeline keeps such descriptions in its registry of data sets
(`pwa_pipeline.orchestration.registry`).
"""

import math
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .._validation import check_name
from ..regressors import n_initial, regressor_dim
from ..scoring.evaluation import WARMUP
from .builtin import DATASETS
from .dataset import Dataset
from .tables import Table, _time_values, read_frame, read_table

#: Share of the data held out for testing when no split is given.
DEFAULT_TEST_FRACTION = 0.25
#: The largest order (na, nb) a registration or a hyper-parameter file accepts: lags per
#: channel, so φ has m·na + r·nb entries and every local set needs three times as many
#: samples; a larger one usually means a sampling rate to lower.
MAX_ORDER = 20
#: What an input or output column's name may hold: it ends MLflow's metric names
#: (``per_output/free_run_nrmse_<name>``), which allow letters, digits, ``_``, ``-``, ``.``,
#: spaces, and on some platforms ``:`` and ``/`` (kept out here: no path, same on every
#: platform).
COLUMN_PATTERN = re.compile(r"[\w .-]+")
#: The longest such name: MLflow's metric names hold at most 250 characters.
MAX_COLUMN_LENGTH = 100
#: Column names that read as experiment ids (case, spaces, ``_`` and ``-`` aside): ``run``,
#: ``run_id``, ``Experiment``, ``trial no``, ``batch``, ``id`` …
EXPERIMENT_NAME = re.compile(r"(?:(?:experiment|exp|run|trial|episode|record|recording|batch"
                             r"|session|sequence|seq|cycle)(?:id|no|nr|num|number)?|id)")
#: Column names that read as time stamps: ``t``, ``time``, ``Time_s``, ``timestamp`` …
TIME_NAME = re.compile(r"(?:t|time|times|timestamp|datetime)(?:s|sec|ms|us|ns)?")


def parse_units(pairs: list[str] | None) -> dict[str, str]:
    """``--units`` as given on the command line, ``NAME=UNIT`` each, as a dict.

    Parameters
    ----------
    pairs : list of str or None
        E.g. ``["q1=deg", "tau1=N·m"]``; the unit is everything after the first ``=`` (it
        may hold spaces when quoted).

    Raises
    ------
    ValueError
        A pair without ``=``, with an empty name or unit, or a name given twice; the
        message names the pair.

    Examples
    --------
    >>> parse_units(["q1=deg", "tau1=N·m"])
    {'q1': 'deg', 'tau1': 'N·m'}
    """
    units: dict[str, str] = {}
    for pair in pairs or ():
        name, eq, unit = pair.partition("=")
        name, unit = name.strip(), unit.strip()
        if not eq or not name or not unit:
            raise ValueError(f"--units {pair!r} is not NAME=UNIT (e.g. y1=deg)")
        if name in units:
            raise ValueError(f"--units gives {name!r} twice ({name}={units[name]}, {pair})")
        units[name] = unit
    return units


def check_column(name: str, kind: str) -> str:
    """``name`` if it can name an input or output (`COLUMN_PATTERN`, at most
    `MAX_COLUMN_LENGTH` characters), else a ValueError stating the rule and a name
    that follows it.

    Examples
    --------
    >>> check_column("temp(degC)", "input")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: input column 'temp(degC)' cannot be used: ... (e.g. 'temp_degC')
    """
    if COLUMN_PATTERN.fullmatch(name) and len(name) <= MAX_COLUMN_LENGTH:
        return name
    fixed = re.sub(r"[^\w .-]+", "_", name).strip("_")[:MAX_COLUMN_LENGTH] or kind[0] + "1"
    shown = name if len(name) <= 80 else name[:77] + "..."
    raise ValueError(f"{kind} column {shown!r} cannot be used: MLflow's metric names, which "
                     f"hold it, allow only letters, digits, '_', '-', '.' and spaces, at most "
                     f"{MAX_COLUMN_LENGTH} characters; rename it (e.g. {fixed!r})")


@dataclass(frozen=True)
class UserDataset:
    """One registered data set.

    Parameters
    ----------
    name : str
        Letters, digits, ``_`` and ``-``; the ``dataset`` partition key.
    path : str
        The ``.csv`` or ``.parquet`` file (stored absolute).
    u, y : tuple of str
        Input and output columns.
    experiment : str, optional
        Column of experiment ids; rows of one id form one experiment (lags never span two).
    time : str, optional
        Numeric or date-time column, strictly increasing within each experiment.
    test_experiments : tuple of str
        Experiment ids held out for testing (needs `experiment`): an id holds out every
        block of rows it has in the file, `<id>#j` only its j-th (`read_table`).
    test_fraction : float, optional
        Without ``test_experiments``: with two or more experiments, the last
        ``round(f · n)`` of them (at least one, at most all but one) in file order; with one,
        the last ``f`` of its samples. Default `DEFAULT_TEST_FRACTION`.
    na, nb : int
        Output and input orders of eq. (3) for every hyper-parameter set that gives none.
    affine : bool
        Constant term of eq. (2).
    units : dict of str to str
        The unit of input and output columns that have one (``{"y1": "deg"}``), shown on
        the figures' axes (``y1 [deg]``); a column not in it has none. Left out of the data
        set's digest, so changing a unit refits and rescores nothing. A registry written
        before units existed loads with none.

    Raises
    ------
    ValueError
        A bad name (`check_name`), an input or output
        column name that MLflow could not log (`check_column`), empty or repeated
        columns, orders outside 1 … `MAX_ORDER`, a
        fraction outside (0, 1), both split rules at once, or a unit for a column that is
        not an input or output, or an empty one.
    """

    name: str
    path: str
    u: tuple[str, ...]
    y: tuple[str, ...]
    experiment: str | None = None
    time: str | None = None
    test_experiments: tuple[str, ...] = field(default=())
    test_fraction: float | None = None
    na: int = 1
    nb: int = 1
    affine: bool = False
    units: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "path", str(Path(self.path).resolve()))
        for key in ("u", "y", "test_experiments"):
            object.__setattr__(self, key, tuple(str(v) for v in getattr(self, key)))
        object.__setattr__(self, "units", {str(k): str(v) for k, v in dict(self.units).items()})
        check_name(self.name, "data set")
        if self.name in DATASETS:
            raise ValueError(f"{self.name!r} is a built-in data set; choose another name")
        if not self.u or not self.y:
            raise ValueError(f"data set {self.name!r} needs at least one input (--u) and one "
                             f"output (--y) column")
        for kind, names in (("input", self.u), ("output", self.y)):
            for column in names:
                check_column(column, kind)
        columns = [*self.u, *self.y, *(c for c in (self.experiment, self.time) if c)]
        repeated = sorted({c for c in columns if columns.count(c) > 1})
        if repeated:
            raise ValueError(f"column(s) {repeated} are given more than once among the "
                             f"inputs, outputs, experiment and time columns")
        for column, unit in self.units.items():
            if column not in (*self.u, *self.y):
                raise ValueError(f"a unit is given for {column!r}, which is not an input (--u) or "
                                 f"output (--y) column; those are {[*self.u, *self.y]}")
            if not unit.strip():
                raise ValueError(f"the unit of {column!r} is empty; leave the column out of "
                                 f"the units to give it none")
        for key in ("na", "nb"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) \
                    or not 1 <= value <= MAX_ORDER:
                raise ValueError(f"{key} must be an integer from 1 to {MAX_ORDER} (lags per "
                                 f"channel), got {value!r}")
        if self.test_experiments and self.test_fraction is not None:
            raise ValueError("give either test experiments or a test fraction, not both")
        if self.test_experiments and self.experiment is None:
            raise ValueError("test experiments need an experiment column (--experiment)")
        fraction = self.test_fraction
        if fraction is not None and not (isinstance(fraction, int | float)
                                         and 0 < fraction < 1):
            raise ValueError(f"the test fraction must lie strictly between 0 and 1, got "
                             f"{fraction!r}")

    def load(self) -> Dataset:
        """Read the file, check it and split it (see the class doc).

        Raises
        ------
        FileNotFoundError, ValueError
            Everything `read_table` checks, unknown test
            experiments, no experiment left for training, an experiment too short for the
            orders or (held out) for the evaluation warm-up, or fewer regressor rows than
            the default local-set size n_ρ = 3d.
        """
        table = read_table(self.path, list(self.u), list(self.y), self.experiment, self.time)
        train, test = self._split(table)
        lag = n_initial(self.na, self.nb)
        for part, pieces, need in (("training", train, lag + 1),
                                   ("held-out", test, max(lag, WARMUP) + 2)):
            for label, u, _ in pieces:
                if len(u) < need:
                    raise ValueError(
                        f"{Path(self.path).name}: {label} has {len(u)} sample(s); a {part} "
                        f"experiment needs at least {need} with na = {self.na}, nb = {self.nb}"
                        + (f" and the evaluation warm-up of {WARMUP}" if part == "held-out"
                           else ""))
        d = regressor_dim(len(self.y), len(self.u), self.na, self.nb, self.affine)
        rows = sum(len(u) - lag for _, u, _ in train)
        if rows < 3 * d:
            raise ValueError(
                f"data set {self.name!r}: the training data give {rows} regressor rows, fewer "
                f"than the default local-set size n_rho = 3d = {3 * d} (d = {d}); use more "
                f"data or lower orders")
        return Dataset(name=self.name, u_train=[u for _, u, _ in train],
                       y_train=[y for _, _, y in train], u_test=[u for _, u, _ in test],
                       y_test=[y for _, _, y in test], u_names=list(self.u),
                       y_names=list(self.y), units=dict(self.units))

    def several_experiments(self) -> str | None:
        """Why the file looks like several experiments although no experiment column is
        given, in one line that names the column to pass (`--experiment`), or None.

        It looks so when a column other than the inputs and outputs has a name that reads
        as experiment ids (`EXPERIMENT_NAME`) and holds two or more of them, each on two
        rows or more, or when the time column (``time``, else one whose name reads as time,
        `TIME_NAME`) goes back. Registration refuses such a file unless the experiment
        column or one record is confirmed.

        Raises
        ------
        FileNotFoundError, ValueError
            The file cannot be read (`read_frame`).
        """
        if self.experiment is not None:
            return None
        frame = read_frame(self.path)
        others = [c for c in frame.columns if c not in (*self.u, *self.y)]

        def reads_as(pattern: re.Pattern, name: object) -> bool:
            return pattern.fullmatch(re.sub(r"[\s_-]+", "", str(name).lower())) is not None

        ids = [c for c in others if c != self.time and reads_as(EXPERIMENT_NAME, c)
               and 2 <= frame[c].nunique() <= len(frame) // 2]
        resets = []
        for c in [self.time] if self.time else [c for c in others if reads_as(TIME_NAME, c)]:
            try:
                t = _time_values(frame[c], Path(self.path).name, c)
            except ValueError:  # no time column (a named one is refused by `read_table`)
                continue
            back = np.flatnonzero(np.diff(t) < 0)
            if back.size:
                resets.append(f"time column {c!r} goes back {back.size} time(s), first at "
                              f"row {back[0] + 1}")
        if not ids and not resets:
            return None
        found = [f"column {c!r} looks like experiment ids ({frame[c].nunique()} values: "
                 f"{', '.join(map(repr, frame[c].drop_duplicates()[:3].tolist()))}"
                 f"{', …' if frame[c].nunique() > 3 else ''})" for c in ids[:1]]
        fix = (f"pass --experiment {ids[0]}" if ids else
               "pass --experiment COLUMN naming the column of experiment ids (add one to the "
               "file if it has none)")
        return (f"{Path(self.path).name} looks like several experiments, not one record: "
                f"{' and '.join([*found, *resets])}; {fix}, or --no-experiment if it is one "
                f"record")

    def _split(self, table: Table) -> tuple[list[tuple], list[tuple]]:
        """The training and held-out pieces, each ``(label, u, y)`` (see the class doc)."""
        pieces = [(f"experiment {e!r}", u, y)
                  for e, u, y in zip(table.ids, table.u, table.y, strict=True)]
        n = len(pieces)
        if self.test_experiments:
            unknown = [e for e in self.test_experiments
                       if e not in table.ids and e not in table.origins]
            if unknown:
                raise ValueError(f"test experiment(s) {unknown} are not in column "
                                 f"{self.experiment!r}; its ids are {table.ids}")
            held = [e in self.test_experiments or o in self.test_experiments
                    for e, o in zip(table.ids, table.origins, strict=True)]
            if all(held):
                raise ValueError("every experiment is held out for testing; none is left "
                                 "for training")
            return ([p for p, h in zip(pieces, held, strict=True) if not h],
                    [p for p, h in zip(pieces, held, strict=True) if h])
        fraction = DEFAULT_TEST_FRACTION if self.test_fraction is None else self.test_fraction
        if n >= 2:
            k = min(max(1, round(fraction * n)), n - 1)
            return pieces[:n - k], pieces[n - k:]
        _, u, y = pieces[0]
        cut = len(u) - math.ceil(fraction * len(u))
        return ([("the training part", u[:cut], y[:cut])],
                [("the held-out part", u[cut:], y[cut:])])

    def orders(self) -> dict:
        """``na``, ``nb`` and ``affine``, as a hyper-parameter table gives them."""
        return {"na": self.na, "nb": self.nb, "affine": self.affine}

    def describe(self) -> dict:
        """The registration as plain values (the registry file's entry)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    def describe_units(self) -> str:
        """The units as ``--units`` takes them, inputs then outputs in column order
        (``u1=N·m y1=deg``), or ``none``."""
        return " ".join(f"{c}={self.units[c]}" for c in (*self.u, *self.y)
                        if c in self.units) or "none"
