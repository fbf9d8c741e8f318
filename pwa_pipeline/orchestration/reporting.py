"""Turning core results into UI metadata and MLflow metrics (no numerics here)."""

import dagster as dg
import numpy as np
import pandas as pd

from ..datasets import Dataset
from ..scoring.comparison import mean_scores
from ..scoring.evaluation import Evaluation, score_text


def rounded(metadata: dict) -> dict:
    """``metadata`` with every float rounded to 4 significant digits (what the UI shows)."""
    return {k: _round4(v) if isinstance(v, float | np.floating) else v
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
    """The regions of a fitted region step: its score rows w_i and intercepts b_i where it
    has them (``coef_``, ``intercept_``: the SVM's argmax), else the inequalities G φ ≤ q of
    each region from ``halfspaces()`` (any region learner), one row per inequality."""
    if hasattr(regions, "coef_"):
        df = pd.DataFrame(regions.coef_, columns=phi_names,
                          index=[f"H{i + 1}" for i in range(regions.n_regions_)])
        df["b"] = regions.intercept_
        return df
    rows, index = [], []
    for i, region in enumerate(regions.halfspaces()):
        if region is not None:
            G, q = region
            rows += [[*g, b] for g, b in zip(G, q, strict=True)]
            index += [f"H{i + 1}.{k + 1}" for k in range(len(q))]
    return pd.DataFrame(rows, columns=[*phi_names, "≤ q"], index=index)


#: The prefix of the per-output metrics in MLflow (its UI groups charts by the part before
#: the slash, so the run's headline metrics stay few and on top).
PER_OUTPUT = "per_output/"
#: The prefix of what a run's model says of itself (sub-models, ε, ground-truth errors), its
#: MLflow params (`model_params`).
MODEL = "model/"


def score_metrics(evaluation: Evaluation) -> dict[str, float]:
    """The MLflow metrics of an evaluation, each to 4 significant digits (what the UI shows).

    Headline: ``one_step_nrmse``, ``one_step_r2``, ``free_run_nrmse``, ``free_run_r2`` (the
    means over the outputs, eq. 23–24), ``free_run_diverged`` (0 or 1), and
    ``one_step_outside_share`` and ``free_run_outside_share``, the share of scored samples
    whose regressor left the model's data envelope (left out for a model without an
    envelope). Per output, under
    `PER_OUTPUT`: ``<mode>_<nrmse|r2|rmse>_<output>``. A diverged free run logs no
    free-run score at all (a 1e30 NRMSE would set the scale of every chart of the
    experiment), neither the mean nor those of its diverged outputs nor its share outside the
    envelope (its non-finite samples count as outside: the onset says more), but where it
    diverged (`Onset`): ``free_run_divergence_experiment``
    and ``free_run_divergence_sample`` (the held-out experiment, from 0, and its sample, the
    warm-up counted) and ``free_run_nrmse_before_divergence``, and its scores as every
    page shows them in the tags ``free_run_nrmse`` and ``free_run_r2`` (`diverged_tags`:
    ``"≥ 10 (diverged)"``, the leaderboard's text); the ``scores.csv`` artifact
    keeps every exact value.
    """
    out: dict[str, float] = {}
    for row in evaluation.table.itertuples(index=False):
        if row.diverged:
            continue
        if row.output == "mean":
            out.update({f"{row.mode}_{k}": getattr(row, k) for k in ("nrmse", "r2")})
        else:
            out.update({f"{PER_OUTPUT}{row.mode}_{k}_{row.output}": getattr(row, k)
                        for k in ("nrmse", "r2", "rmse")})
    if "outside_share" in evaluation.table:
        means = evaluation.table[evaluation.table["output"] == "mean"]
        out.update({f"{mode}_outside_share": share for mode, share, diverged in
                    zip(means["mode"], means["outside_share"], means["diverged"], strict=True)
                    if np.isfinite(share) and not diverged})
    onset = evaluation.onset
    out["free_run_diverged"] = float(onset is not None)
    if onset is not None:
        out["free_run_divergence_experiment"] = onset.experiment
        out["free_run_divergence_sample"] = onset.sample
        if np.isfinite(onset.nrmse_before):
            out["free_run_nrmse_before_divergence"] = onset.nrmse_before
    return {k: _round4(v) for k, v in out.items()}


def model_params(facts: dict) -> dict[str, str]:
    """What a model says of itself (sub-models, output groups, ε, the ground truth's
    errors, the structure search's verdict, the export's regions) as MLflow params under
    `MODEL`: facts of the run, one value each, shown in its parameters table and never
    drawn as charts (a boolean as a bar, a count as a line, ahead of the scores). Numbers
    to 4 significant digits, booleans `true`/`false`; a fact that is not finite (a
    comparison that does not apply) is left out."""
    out = {}
    for key, value in facts.items():
        if isinstance(value, bool | np.bool_):
            text = "true" if value else "false"
        elif isinstance(value, int | np.integer):
            text = str(int(value))
        elif isinstance(value, float | np.floating):
            if not np.isfinite(value):
                continue
            text = f"{float(value):.4g}"
        else:
            text = str(value)
        out[f"{MODEL}{key}"] = text
    return out


def _round4(value: float) -> float:
    return float(f"{float(value):.4g}")


def nrmse_summary(table: pd.DataFrame) -> dict[str, float | str]:
    """NRMSE per output and mode, for the asset's metadata: a number, or for a diverged
    run `score_text`'s ``"≥ 10 (diverged)"`` (text, which the asset's plots leave out
    rather than drawing a 1e30 spike)."""
    return {f"nrmse {row.mode} {row.output}":
            score_text(row.nrmse, "nrmse", True) if row.diverged else float(row.nrmse)
            for row in table.itertuples(index=False)}


def diverged_tags(evaluation: Evaluation) -> dict[str, str]:
    """What a diverged free run shows in MLflow in place of its scores (`score_metrics`
    logs none): the tags ``free_run_nrmse`` and ``free_run_r2`` holding `score_text`'s
    ``"≥ 10 (diverged)"`` and ``"≤ -99 (diverged)"``, as the leaderboard and the Dagster
    pages show them; none for a run that did not diverge."""
    if not evaluation.diverged():
        return {}
    return {f"free_run_{metric}": score_text(evaluation.mean("free_run", metric), metric, True)
            for metric in ("nrmse", "r2")}


def mean_scores_markdown(table: pd.DataFrame) -> str:
    """`pwa_pipeline.scoring.comparison.mean_scores` of ``table`` as Markdown (the
    comparison page, the command line's table per partition), a diverged free run's scores
    as `score_text` shows them."""
    wide = mean_scores(table)
    diverged = wide.pop("free-run diverged").fillna(False).astype(bool) \
        if "free-run diverged" in wide else pd.Series(False, index=wide.index)
    shown = pd.DataFrame({column: [
        score_text(v, "nrmse" if column.startswith("NRMSE") else "r2",
                   d and column.endswith("free_run"))
        for v, d in zip(wide[column], diverged, strict=True)] for column in wide},
        index=wide.index)
    return shown.to_markdown()


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
    """The leaderboard (`pwa_pipeline.scoring.comparison.leaderboard`) as Markdown: one
    table per data set, each method named with what its model is when the name does not say
    it (``pwa — linear kept (no switching structure beat it held out)``, the table's ``model``),
    numbers to 4 significant digits, a diverged free run's scores as `score_text` shows
    them everywhere (``≥ 10 (diverged)``, ``≤ -99 (diverged)``); then the partitions never
    materialised (``missing``: key → methods)."""
    parts = []
    for dataset, rows in table.groupby("dataset", sort=False):
        shown = pd.DataFrame({
            "rank": rows["rank"],
            "method": [f"{method} — {note}" if note else method
                       for method, note in zip(rows["method"], rows["model"], strict=True)],
            "hparams": rows["hparams"],
            "one-step NRMSE": rows["one_step_nrmse"].map(_sig4),
            "one-step R²": rows["one_step_r2"].map(_sig4),
            "free-run NRMSE": [score_text(v, "nrmse", d) for v, d in zip(
                rows["free_run_nrmse"], rows["free_run_diverged"], strict=True)],
            "free-run R²": [score_text(v, "r2", d) for v, d in zip(
                rows["free_run_r2"], rows["free_run_diverged"], strict=True)]})
        parts.append(f"### {dataset}\n\n{shown.to_markdown(index=False)}")
    if table.empty:
        parts.append("No partition has been materialised yet.")
    if missing:
        lines = "\n".join(f"- `{key}`: {', '.join(methods)}"
                          for key, methods in missing.items())
        parts.append(f"Not materialised (partition: methods without scores):\n\n{lines}")
    return "\n\n".join(parts) + "\n"
