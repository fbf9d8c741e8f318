"""Users' own data: CSV or Parquet tables with named input/output columns."""

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._typing import Float2D
from .._validation import MAX_MAGNITUDE
from .dataset import Dataset


def _shown(cell: object) -> str:
    """A table cell as error messages show it: quoted if text, 'NaN or empty' if missing."""
    import pandas as pd

    if pd.api.types.is_scalar(cell) and pd.isna(cell):
        return "NaN or empty"
    return repr(cell) if isinstance(cell, str) else str(cell)


@dataclass(frozen=True)
class Table:
    """A user table split into experiments (in the order they first appear in the file).

    Attributes
    ----------
    u, y : lists of ndarrays of shapes (N_e, r) and (N_e, m)
    ids : list of str
        Each experiment's id as text (`"0"` without an experiment column); the j-th
        separate block of rows of one id (j ≥ 2) is the experiment `<id>#j`.
    origins : list of str
        Each experiment's id in the file (`<id>` for `<id>#j`).
    """

    u: list[Float2D]
    y: list[Float2D]
    ids: list[str]
    origins: list[str]


def read_table(
    path: str | os.PathLike,
    u_columns: list[str],
    y_columns: list[str],
    experiment_column: str | None = None,
    time_column: str | None = None,
) -> Table:
    """Read and check a CSV or Parquet table with named input and output columns.

    Parameters
    ----------
    path : path-like
        A ``.csv`` or ``.parquet`` file.
    u_columns, y_columns : list of str
        Column names of the inputs and outputs.
    experiment_column : str, optional
        Column identifying separate experiments (rows kept in file order within each): each
        block of consecutive rows with one id is an experiment, a later block of an id
        that appeared before is `<id>#2`, `<id>#3` … (its rows do not follow the
        earlier block's, so no lag spans the gap).
    time_column : str, optional
        Numeric or date-time column that must increase strictly within each experiment; the
        rows are not reordered, so an unsorted or repeated time is an error.

    Returns
    -------
    Table

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, unknown format, a file that cannot be read as its format (empty,
        binary), a column named twice in a CSV header, missing columns, no data rows, an
        empty experiment id, a block's name `<id>#j` that is another id, a u/y column of
        date-times or booleans, a non-numeric, missing,
        infinite or huge (beyond ``MAX_MAGNITUDE``) value in the u/y columns, an output that holds
        one value in every row, or a missing, repeated or decreasing time. Each message names
        the file; rows are numbered from 0 in file order, not counting the header.
    """
    import pandas as pd

    p = Path(path)
    df = read_frame(p)
    extra = [c for c in (experiment_column, time_column) if c]
    wanted = list(u_columns) + list(y_columns) + extra
    twice = _repeated_header(p, wanted) if p.suffix.lower() == ".csv" else []
    if twice:
        raise ValueError(f"{p.name} names column(s) {twice} more than once in its header; "
                         f"rename them so that each column has its own name")
    missing = [c for c in wanted if c not in df.columns]
    if missing:
        raise ValueError(f"{p.name} has no column(s) {missing}; it has {list(df.columns)}")
    if df.empty:
        raise ValueError(f"{p.name} has a header but no data rows")
    for c in list(u_columns) + list(y_columns):
        if not (pd.api.types.is_numeric_dtype(df[c]) or pd.api.types.is_object_dtype(df[c])
                or pd.api.types.is_string_dtype(df[c])) or pd.api.types.is_bool_dtype(df[c]):
            raise ValueError(f"{p.name}: column {c!r} holds {df[c].dtype} values, not numbers; "
                             f"an input or output must be numeric (a date-time goes to --time)")
        values = pd.to_numeric(df[c], errors="coerce").astype(float)
        bad = np.flatnonzero(~np.isfinite(values.to_numpy()))
        if bad.size:
            raise ValueError(
                f"{p.name}: column {c!r} has {bad.size} non-numeric, missing or infinite value(s) "
                f"(first: {_shown(df[c].iloc[bad[0]])} at row {bad[0]})"
            )
        huge = np.flatnonzero(np.abs(values.to_numpy()) > MAX_MAGNITUDE)
        if huge.size:
            raise ValueError(
                f"{p.name}: column {c!r} has {huge.size} value(s) beyond ±{MAX_MAGNITUDE:g} (first: "
                f"{values.iloc[huge[0]]:g} at row {huge[0]}), whose squares overflow the least "
                f"squares; rescale the column")
        df[c] = values
    constant = [c for c in y_columns if len(df) > 1 and df[c].nunique() == 1]
    if constant:
        raise ValueError(f"{p.name}: output column(s) {constant} hold one value in every row "
                         f"(e.g. {df[constant[0]].iloc[0]:g}): there is nothing to identify; "
                         f"leave them out of the outputs")
    if experiment_column is None:
        groups = [("0", df)]
    else:
        no_id = np.flatnonzero(df[experiment_column].isna().to_numpy())
        if no_id.size:
            raise ValueError(
                f"{p.name}: column {experiment_column!r} is empty in {no_id.size} row(s) "
                f"(first: row {no_id[0]}); every row needs an experiment id"
            )
        groups = _blocks(df, experiment_column, p.name)
    if time_column is not None:
        times = _time_values(df[time_column], p.name, time_column)
        for key, g in groups:
            _check_increasing(times[g.index.to_numpy()], g.index.to_numpy(), p.name,
                              time_column, key if experiment_column else None)
    return Table(u=[g[list(u_columns)].to_numpy(dtype=float) for _, g in groups],
                 y=[g[list(y_columns)].to_numpy(dtype=float) for _, g in groups],
                 ids=[k for k, _ in groups],
                 origins=[k if experiment_column is None else str(g[experiment_column].iloc[0])
                          for k, g in groups])


def _blocks(df, column: str, file: str) -> list[tuple[str, object]]:
    """The experiments of `df`: each run of consecutive rows with one id in `column`,
    in file order, named by the id, and `<id>#j` for the j-th separate run of an id
    (j ≥ 2): rows apart in the file are not consecutive samples, so no lag spans the gap."""
    ids = df[column]
    start = (ids != ids.shift()).to_numpy()
    runs, seen, out = np.cumsum(start), {}, []
    given = set(ids.astype(str))
    for _, g in df.groupby(runs, sort=True):
        key = str(g[column].iloc[0])
        seen[key] = seen.get(key, 0) + 1
        name = key if seen[key] == 1 else f"{key}#{seen[key]}"
        if seen[key] > 1 and name in given:
            raise ValueError(f"{file}: experiment id {key!r} appears in separate blocks of "
                             f"rows, and {name!r}, the name of its block {seen[key]}, is "
                             f"another id of column {column!r}; give each block its own id")
        out.append((name, g))
    return out


def read_frame(path: str | os.PathLike):
    """A CSV or Parquet file as a pandas DataFrame, rows numbered from 0, unchecked.

    Raises
    ------
    FileNotFoundError, ValueError
        A missing file, another format, or a file that cannot be read as its format (empty,
        binary); each message names the file.
    """
    import pandas as pd

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"data file not found: {p.resolve()}")
    readers = {".csv": pd.read_csv, ".parquet": pd.read_parquet}
    if p.suffix.lower() not in readers:
        raise ValueError(f"unsupported file type {p.suffix!r} for {p}: use .csv or .parquet")
    try:
        return readers[p.suffix.lower()](p).reset_index(drop=True)
    except (ValueError, UnicodeDecodeError, OSError) as exc:  # (pandas' and pyarrow's errors)
        raise ValueError(f"{p} cannot be read as a {p.suffix.lower()[1:]} table: "
                         f"{type(exc).__name__}: {exc}") from None


def _repeated_header(path: Path, names: list[str]) -> list[str]:
    """The ``names`` that the CSV file's header line holds more than once (pandas would
    rename the later ones and read the first without a word)."""
    import csv

    with path.open(newline="", encoding="utf-8", errors="replace") as fh:
        header = next(csv.reader(fh), [])
    return [n for n in dict.fromkeys(names) if header.count(n) > 1]


def _time_values(column, file: str, name: str) -> np.ndarray:
    """A time column as float64 (numbers) or int64 nanoseconds (date-times)."""
    import pandas as pd

    numeric = pd.to_numeric(column, errors="coerce")
    if numeric.notna().all():
        return numeric.to_numpy(dtype=float)
    if numeric.notna().any():
        bad = int(np.flatnonzero(numeric.isna().to_numpy())[0])
        raise ValueError(f"{file}: time column {name!r} has a non-numeric or missing value "
                         f"({_shown(column.iloc[bad])} at row {bad})")
    stamps = pd.to_datetime(column, errors="coerce", format="mixed")
    if stamps.isna().any():
        bad = int(np.flatnonzero(stamps.isna().to_numpy())[0])
        raise ValueError(f"{file}: time column {name!r} is neither numeric nor a date-time "
                         f"({_shown(column.iloc[bad])} at row {bad})")
    return stamps.to_numpy().astype("datetime64[ns]").astype(np.int64)


def _check_increasing(t: np.ndarray, rows: np.ndarray, file: str, name: str,
                      experiment: str | None) -> None:
    """Raise a ValueError at the first repeated or decreasing time of one experiment."""
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0)
    if not bad.size:
        return
    i = bad[0]
    where = f" in experiment {experiment!r}" if experiment is not None else ""
    what = "repeated" if step[i] == 0 else "decreasing (the rows are not sorted by time)"
    raise ValueError(f"{file}: time column {name!r} is {what}{where}: row {rows[i + 1]} "
                     f"follows row {rows[i]}; {bad.size} such row(s) in all")


def load_table(
    path: str | os.PathLike,
    u_columns: list[str],
    y_columns: list[str],
    experiment_column: str | None = None,
    time_column: str | None = None,
) -> Dataset:
    """A CSV or Parquet table as a data set: every experiment (one per id of
    ``experiment_column``, else the whole table) for training, none held out (split it with
    [`UserDataset`][pwa_pipeline.datasets.UserDataset], or pass ``u_train[:k]``).

    See `read_table` for the parameters and the errors.

    Returns
    -------
    Dataset
        Named after the file, its channels after the columns.
    """
    table = read_table(path, u_columns, y_columns, experiment_column, time_column)
    return Dataset(Path(path).stem, table.u, table.y, [], [], list(u_columns),
                   list(y_columns))
