"""Users' own data: CSV or Parquet tables with named input/output columns."""

import os
from pathlib import Path

from .._typing import Float2D


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
