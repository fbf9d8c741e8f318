"""Comparison tables of the methods' scores: the paper's Table 1 layout and mean scores."""

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


def table1(scores: pd.DataFrame, dataset: str, mode: str) -> pd.DataFrame:
    """NRMSE and R² (%) per output and method, like the paper's Table 1, for one mode.

    ``scores`` has columns dataset, method, mode, output, nrmse, r2 (fraction), and
    optionally hparams (several sets of one method then get a column each). Methods are
    ordered as in :data:`pwa_pipeline.methods.METHODS`; a method not there raises.
    """
    from ..methods import METHODS

    sel = scores[(scores["dataset"] == dataset) & (scores["mode"] == mode)]
    sel = sel.assign(column=_column_labels(sel))
    wide = sel.pivot_table(index="output", columns="column", values=["nrmse", "r2"], sort=False)
    wide["r2"] = wide["r2"] * 100
    order = _ordered(sel["column"], list(METHODS))
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
