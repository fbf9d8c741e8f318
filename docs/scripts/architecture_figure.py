"""Draw the architecture diagram of docs/architecture.md.

    python docs/scripts/architecture_figure.py     # writes docs/figures/architecture.png

The diagram reads left to right as a fit travels: data → the method's steps → the fitted
model → the Dagster pipeline → MLflow. Every name in it is written once, in :data:`DIAGRAM`,
with the object of the code it stands for (``module:attribute``, or ``asset:key`` for an
asset of the pipeline's definitions); ``tests/test_architecture.py`` resolves each one, so a
class or asset renamed or moved fails the suite until the diagram follows.
"""

from pathlib import Path
from typing import NamedTuple

OUT = Path(__file__).resolve().parents[1] / "figures" / "architecture.png"


class Entry(NamedTuple):
    label: str  # what the box shows
    ref: str  # the object of the code: "module:attribute" or "asset:key"
    indent: int = 0  # 1 = a part of the entry above it


class Column(NamedTuple):
    title: str
    package: str
    entries: tuple[Entry, ...]
    flows: str  # what goes on to the next column


DIAGRAM: tuple[Column, ...] = (
    Column("data", "pwa_pipeline.datasets", (
        Entry("Dataset", "pwa_pipeline.datasets.dataset:Dataset"),
        Entry("u_train, y_train, u_test, y_test", "pwa_pipeline.datasets.dataset:Dataset", 1),
        Entry("make_hure_vasak", "pwa_pipeline.datasets.simulated:make_hure_vasak"),
        Entry("load_kuka", "pwa_pipeline.datasets.kuka:load_kuka"),
        Entry("load_table (CSV, Parquet)", "pwa_pipeline.datasets.tables:load_table"),
        Entry("build_regressors: φ(k)", "pwa_pipeline.regressors:build_regressors"),
    ), "u, y"),
    Column("steps (paper §3)", "pwa_pipeline.pwa.steps", (
        Entry("2–3  LocalLeastSquares: θ_k", "pwa_pipeline.pwa.steps.local_models:LocalLeastSquares"),
        Entry("4  DBSCANClustering", "pwa_pipeline.pwa.steps.clustering:DBSCANClustering"),
        Entry("5  RefinedSubModels: θ_i", "pwa_pipeline.pwa.steps.submodels.refined:RefinedSubModels"),
        Entry("6  SVMRegions | ResidualRegions", "pwa_pipeline.pwa.steps.base:BaseRegions"),
        Entry("StructureSearch", "pwa_pipeline.pwa.search:StructureSearch"),
        Entry("OutputErrorRefinement", "pwa_pipeline.pwa.output_error:OutputErrorRefinement"),
    ), "θ_i, H_i"),
    Column("model", "pwa_pipeline.pwa", (
        Entry("PWARX.fit(u, y)", "pwa_pipeline.pwa.estimator:PWARX"),
        Entry("groups_: OutputGroup", "pwa_pipeline.pwa.groups:OutputGroup", 1),
        Entry("regions: RegionMap", "pwa_pipeline.pwa.partitions:RegionMap", 1),
        Entry("predict, simulate, score", "pwa_pipeline.pwa.arx:ARXModelBase"),
        Entry("to_state_space: PWAStateSpace", "pwa_pipeline.control.state_space:PWAStateSpace"),
        Entry("LinearARX, SubspaceSS", "pwa_pipeline.baselines:SubspaceSS"),
    ), "models"),
    Column("pipeline", "pwa_pipeline.orchestration", (
        Entry("PartitionKey: data set | set", "pwa_pipeline.orchestration.partitions:PartitionKey"),
        Entry("configuration", "asset:configuration"),
        Entry("raw_benchmark", "asset:raw_benchmark"),
        Entry("pwa_fit → pwa_model", "asset:pwa_model"),
        Entry("regressors … svm_regions", "asset:svm_regions", 1),
        Entry("*_scores, comparison", "asset:comparison"),
        Entry("control_model, leaderboard", "asset:control_model"),
    ), "runs"),
    Column("MLflow", "orchestration.tracking", (
        Entry("method_run: one run per method", "pwa_pipeline.orchestration.run_records:method_run"),
        Entry("params: resolved_params", "pwa_pipeline.pwa.estimator:PWARX", 1),
        Entry("metrics: NRMSE, R²", "pwa_pipeline.scoring.evaluation:Evaluation", 1),
        Entry("figures, tables", "pwa_pipeline.orchestration.images:png_markdown", 1),
        Entry("MLflowTracker", "pwa_pipeline.orchestration.tracking:MLflowTracker"),
        Entry("registered pyfunc model", "pwa_pipeline.orchestration.mlflow_models:Simulator"),
    ), ""),
)


def draw(path: Path = OUT) -> None:
    """Five columns of boxes joined by arrows that name what flows between them."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    width, gap, top, line = 2.55, 0.65, 4.25, 0.42
    fig = Figure(figsize=(5 * width + 4 * gap + 0.3, 4.4))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(-0.15, 5 * width + 4 * gap + 0.15)
    ax.set_ylim(0, 4.4)
    ax.axis("off")
    fill, edge, ink = "#e8eef6", "#4a6b8f", "#1d2b3a"
    height = 0.9 + line * max(len(column.entries) for column in DIAGRAM)
    for i, column in enumerate(DIAGRAM):
        x = i * (width + gap)
        ax.add_patch(FancyBboxPatch((x, top - height), width, height, facecolor=fill,
                                    edgecolor=edge, boxstyle="round,pad=0.02,rounding_size=0.08"))
        ax.text(x + width / 2, top - 0.25, column.title, ha="center", va="center",
                fontsize=13, weight="bold", color=ink)
        ax.text(x + width / 2, top - 0.55, column.package, ha="center", va="center",
                fontsize=8, family="monospace", color=edge)
        for j, entry in enumerate(column.entries):
            ax.text(x + 0.12 + 0.18 * entry.indent, top - 0.95 - line * j, entry.label,
                    ha="left", va="center", fontsize=8.5 - 0.5 * entry.indent, color=ink)
        if column.flows:
            y = top - 1.2
            ax.add_patch(FancyArrowPatch((x + width + 0.03, y), (x + width + gap - 0.03, y),
                                         arrowstyle="-|>", mutation_scale=16, color=edge))
            ax.text(x + width + gap / 2, y + 0.18, column.flows, ha="center", fontsize=8,
                    color=edge)
    ax.text(0.0, 0.12, "Arrows: what a fit hands on. The imports follow the layers of "
            "docs/architecture.md, which tests/test_architecture.py checks.",
            fontsize=8.5, color=edge)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    draw()
    print(f"wrote {OUT}")
