"""Users' own data: CSV or Parquet tables with named input/output columns."""

import os
from pathlib import Path

import numpy as np

from .._typing import Float2D


def _shown(cell: object) -> str:
    """A table cell as error messages show it: quoted if text, 'NaN or empty' if missing."""
    import pandas as pd

    if pd.api.types.is_scalar(cell) and pd.isna(cell):
        return "NaN or empty"
    return repr(cell) if isinstance(cell, str) else str(cell)


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
        Missing file, unknown format, missing columns, an empty experiment id, or a
        non-numeric, missing or infinite value in the u/y columns. Rows are numbered from 0
        in file order, not counting the header.
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
    for c in list(u_columns) + list(y_columns):
        values = pd.to_numeric(df[c], errors="coerce").astype(float)
        bad = np.flatnonzero(~np.isfinite(values.to_numpy()))
        if bad.size:
            raise ValueError(
                f"{p.name}: column {c!r} has {bad.size} non-numeric, missing or infinite value(s) "
                f"(first: {_shown(df[c].iloc[bad[0]])} at row {bad[0]})"
            )
        df[c] = values
    if experiment_column is None:
        groups = [df]
    else:
        no_id = np.flatnonzero(df[experiment_column].isna().to_numpy())
        if no_id.size:
            raise ValueError(
                f"{p.name}: column {experiment_column!r} is empty in {no_id.size} row(s) "
                f"(first: row {no_id[0]}); every row needs an experiment id"
            )
        groups = [g for _, g in df.groupby(experiment_column, sort=False)]
    u = [g[list(u_columns)].to_numpy(dtype=float) for g in groups]
    y = [g[list(y_columns)].to_numpy(dtype=float) for g in groups]
    return u, y
