"""Comparison tables of the methods' scores: the paper's Table 1 layout, mean scores, the
leaderboard."""

import numpy as np
import pandas as pd


def _column_labels(scores: pd.DataFrame) -> pd.Series:
    """``<method>`` or, with an ``hparams`` column, ``<method> (<hparams>)``."""
    if "hparams" in scores:
        return scores["method"] + " (" + scores["hparams"].astype(str) + ")"
    return scores["method"]


def _ordered(labels, methods: list[str]) -> list[str]:
    """Labels in registry order of their method, then as they come."""
    rank = {m: i for i, m in enumerate(methods)}
    unknown = sorted({lab.split(" (")[0] for lab in labels} - set(rank))
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; the methods are {methods}")
    return sorted(dict.fromkeys(labels), key=lambda lab: rank[lab.split(" (")[0]])


def table1(scores: pd.DataFrame, dataset: str, mode: str, methods: list[str]
           ) -> pd.DataFrame:
    """NRMSE and R² (%) per output and method, like the paper's Table 1, for one mode.

    ``scores`` has columns dataset, method, mode, output, nrmse, r2 (fraction), and
    optionally hparams (several sets of one method then get a column each). Methods are
    ordered as in ``methods`` (e.g. ``list(pwa_pipeline.methods.METHODS)``); a method not
    there raises.
    """
    sel = scores[(scores["dataset"] == dataset) & (scores["mode"] == mode)]
    sel = sel.assign(column=_column_labels(sel))
    wide = sel.pivot_table(index="output", columns="column", values=["nrmse", "r2"], sort=False)
    wide["r2"] = wide["r2"] * 100
    order = _ordered(sel["column"], methods)
    return wide[[(k, c) for c in order for k in ("nrmse", "r2")]].set_axis(
        [f"{c} {'NRMSE' if k == 'nrmse' else 'R² %'}" for c in order for k in ("nrmse", "r2")],
        axis=1)


def mean_scores(table: pd.DataFrame) -> pd.DataFrame:
    """Output-averaged NRMSE and R² per method (rows) and mode (columns), diverged runs
    marked; ``table`` has columns method, mode, output, nrmse, r2 and diverged."""
    means = table[table["output"] == "mean"]
    wide = means.pivot_table(index="method", columns="mode", values=["nrmse", "r2"],
                             sort=False)
    wide.columns = [f"{'NRMSE' if k == 'nrmse' else 'R²'} {mode}" for k, mode in wide.columns]
    if "diverged" in means:
        wide["free-run diverged"] = means[means["mode"] == "free_run"].set_index(
            "method")["diverged"]
    return wide


#: Columns of `leaderboard`.
LEADERBOARD_COLUMNS = ["dataset", "rank", "method", "hparams", "one_step_nrmse", "one_step_r2",
                       "free_run_nrmse", "free_run_r2", "free_run_diverged", "model"]


def leaderboard(scores: pd.DataFrame, methods: list[str]) -> pd.DataFrame:
    """Every data set × hyper-parameter set × method in one table, ranked by free run.

    ``scores`` has columns dataset, hparams, method, mode, output, nrmse, r2 and diverged
    (evaluation tables stacked, one per partition and method), and optionally model (what
    the fitted model is when its method's name does not say it, e.g. a structure search
    that kept the linear model; ``""`` when it does). Each row holds the output-averaged
    NRMSE and R² of one-step prediction and free run, whether the free run diverged, and
    ``model`` (``""`` without that column); ``rank`` orders the rows of a data set by
    free-run NRMSE (1 is best, ties share a rank, a diverged or non-finite free run ranks
    last). Rows are sorted by data set (as they come), rank, then method (in the order of
    ``methods``) and set. No score: no row.
    """
    means = scores[scores["output"] == "mean"]
    if means.empty:  # nothing scored yet: the table's columns, no row
        return pd.DataFrame(columns=LEADERBOARD_COLUMNS)
    keys = ["dataset", "hparams", "method"]
    # unstack, not pivot_table: a NaN score keeps its row, and no absent combination appears
    wide = means.set_index([*keys, "mode"])[["nrmse", "r2"]].unstack("mode")
    wide.columns = [f"{mode}_{metric}" for metric, mode in wide.columns]
    free = means[means["mode"] == "free_run"].set_index(keys)["diverged"].astype(bool)
    if "model" not in means:  # scores stored before the column existed
        means = means.assign(model="")
    notes = means.groupby(keys, sort=False)["model"].first()
    table = wide.join(free.rename("free_run_diverged")).join(notes).reset_index()
    table["free_run_diverged"] = table["free_run_diverged"].fillna(False).astype(bool)
    table["model"] = table["model"].fillna("").astype(str)
    finite = table["free_run_nrmse"].where(~table["free_run_diverged"]
                                           & np.isfinite(table["free_run_nrmse"]), np.inf)
    table["rank"] = finite.groupby(table["dataset"], sort=False).rank(method="min").astype(int)
    order = {m: i for i, m in enumerate(methods)}
    datasets = {d: i for i, d in enumerate(dict.fromkeys(scores["dataset"]))}
    table = table.assign(_d=table["dataset"].map(datasets),
                         _m=table["method"].map(order).fillna(len(order)))
    table = table.sort_values(["_d", "rank", "_m", "hparams"], kind="stable")
    return table[LEADERBOARD_COLUMNS].reset_index(drop=True)
