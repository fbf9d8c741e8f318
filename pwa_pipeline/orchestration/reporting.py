"""Turning core results into UI metadata and MLflow metrics (no numerics here)."""

import dagster as dg
import numpy as np
import pandas as pd

from ..datasets import Dataset
from ..scoring.evaluation import DIVERGENCE


def rounded(metadata: dict) -> dict:
    """``metadata`` with every float rounded to 4 significant digits (what the UI shows)."""
    return {k: float(f"{v:.4g}") if isinstance(v, float | np.floating) else v
            for k, v in metadata.items()}


def markdown(table: pd.DataFrame) -> dg.MetadataValue:
    """A table as Markdown metadata, numbers to 4 significant digits."""
    return dg.MetadataValue.md(table.to_markdown(floatfmt=".4g"))


def params_table(params: dict) -> pd.DataFrame:
    """Parameters as a two-column table (name, value), values as text."""
    return pd.DataFrame({"value": [str(v) for v in params.values()]},
                        index=pd.Index(list(params), name="parameter"))


def theta_table(thetas: np.ndarray, phi_names: list[str], y_names: list[str]) -> pd.DataFrame:
    """θ_i as one table: a row per regressor, a column per (sub-model, output)."""
    cols = {f"θ{i + 1}:{y}": thetas[i][:, j] for i in range(thetas.shape[0])
            for j, y in enumerate(y_names)}
    return pd.DataFrame(cols, index=phi_names)


def regions_table(regions, phi_names: list[str]) -> pd.DataFrame:
    """The rows w_i and intercepts b_i of a fitted region step (``coef_``, ``intercept_``)."""
    df = pd.DataFrame(regions.coef_, columns=phi_names,
                      index=[f"H{i + 1}" for i in range(regions.n_regions_)])
    df["b"] = regions.intercept_
    return df


def score_metrics(table: pd.DataFrame) -> dict[str, float]:
    """``{<mode>_<metric>_<output>: value}`` from an evaluation table, for MLflow.

    A diverged run's NRMSE is capped at the divergence limit and its R² at 1 − limit² (a
    1e30 free run would flatten every chart of the experiment), its RMSE is left out, and
    ``free_run_diverged`` is 1; the ``scores.csv`` artifact keeps the exact values.
    """
    out = {}
    for row in table.itertuples(index=False):
        stem = f"{row.mode}_{{}}_{row.output}"
        if row.diverged:
            out[stem.format("nrmse")] = float(np.fmin(row.nrmse, DIVERGENCE))
            out[stem.format("r2")] = float(np.fmax(row.r2, 1 - DIVERGENCE**2))
        else:
            out.update({stem.format(k): float(getattr(row, k)) for k in ("nrmse", "r2", "rmse")})
    out["free_run_diverged"] = float(table.loc[table["mode"] == "free_run", "diverged"].any())
    return out


def nrmse_summary(table: pd.DataFrame) -> dict[str, float]:
    """NRMSE per output and mode, for the asset's metadata."""
    return {f"nrmse {row.mode} {row.output}": float(row.nrmse)
            for row in table.itertuples(index=False)}


def training_table(data: Dataset) -> pd.DataFrame:
    """The training experiments as one table: inputs, outputs, and the experiment of each row
    (``"0"``, ``"1"``, ...)."""
    table = pd.DataFrame(np.column_stack([np.concatenate(data.u_train),
                                          np.concatenate(data.y_train)]),
                         columns=data.u_names + data.y_names)
    table["experiment"] = np.repeat([str(i) for i in range(len(data.u_train))],
                                    [len(u) for u in data.u_train])
    return table


def _sig4(value: float) -> str:
    return f"{value:.4g}"


def leaderboard_markdown(table: pd.DataFrame, missing: dict[str, list[str]] | None = None
                         ) -> str:
    """The leaderboard (:func:`pwa_pipeline.scoring.comparison.leaderboard`) as Markdown: one
    table per data set, numbers to 4 significant digits, a diverged free run shown as
    :func:`score_metrics` logs it (NRMSE capped at the divergence limit, R² at 1 − limit²)
    and flagged; then the partitions never materialised (``missing``: key → methods)."""
    parts = []
    for dataset, rows in table.groupby("dataset", sort=False):
        shown = pd.DataFrame({
            "rank": rows["rank"], "method": rows["method"], "hparams": rows["hparams"],
            "one-step NRMSE": rows["one_step_nrmse"].map(_sig4),
            "one-step R²": rows["one_step_r2"].map(_sig4),
            "free-run NRMSE": [f"≥ {_sig4(DIVERGENCE)} (diverged)" if d else _sig4(v)
                               for v, d in zip(rows["free_run_nrmse"],
                                               rows["free_run_diverged"], strict=True)],
            "free-run R²": [f"≤ {_sig4(1 - DIVERGENCE**2)} (diverged)" if d else _sig4(v)
                            for v, d in zip(rows["free_run_r2"], rows["free_run_diverged"],
                                            strict=True)]})
        parts.append(f"### {dataset}\n\n{shown.to_markdown(index=False)}")
    if table.empty:
        parts.append("No partition has been materialised yet.")
    if missing:
        lines = "\n".join(f"- `{key}`: {', '.join(methods)}"
                          for key, methods in missing.items())
        parts.append(f"Not materialised (partition: methods without scores):\n\n{lines}")
    return "\n\n".join(parts) + "\n"
