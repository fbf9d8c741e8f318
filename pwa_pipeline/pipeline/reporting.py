"""Turning core results into UI metadata and MLflow metrics (no numerics here)."""

import numpy as np
import pandas as pd

from ..regions import Regions


def theta_table(thetas: np.ndarray, phi_names: list[str], y_names: list[str]) -> pd.DataFrame:
    """θ_i as one table: a row per regressor, a column per (sub-model, output)."""
    cols = {f"θ{i + 1}:{y}": thetas[i][:, j] for i in range(thetas.shape[0])
            for j, y in enumerate(y_names)}
    return pd.DataFrame(cols, index=phi_names)


def regions_table(regions: Regions, phi_names: list[str]) -> pd.DataFrame:
    """The region classifier's rows w_i and intercepts b_i."""
    df = pd.DataFrame(regions.coef, columns=phi_names,
                      index=[f"H{i + 1}" for i in range(regions.n_regions)])
    df["b"] = regions.intercept
    return df


def score_metrics(table: pd.DataFrame) -> dict[str, float]:
    """``{<mode>_<metric>_<output>: value}`` from an evaluation table."""
    out = {}
    for row in table.itertuples(index=False):
        for metric in ("nrmse", "r2", "rmse"):
            out[f"{row.mode}_{metric}_{row.output}"] = float(getattr(row, metric))
    return out


def nrmse_summary(table: pd.DataFrame) -> dict[str, float]:
    """NRMSE per output and mode, for the asset's metadata."""
    return {f"nrmse {row.mode} {row.output}": float(row.nrmse)
            for row in table.itertuples(index=False)}
