"""The Dagster layer: definitions, materialisation, MLflow tracking, schedule, storage."""

import base64
import json
import logging
import shutil
import time
from pathlib import Path

import dagster as dg
import joblib
import mlflow
import numpy as np
import pandas as pd
import pytest

from pwa_pipeline import PWARX, LinearARX, SubspaceSS
from pwa_pipeline.config import BUNDLED_HPARAMS
from pwa_pipeline.control import PWAStateSpace
from pwa_pipeline.definitions import defs
from pwa_pipeline.methods import METHODS
from pwa_pipeline.orchestration import images, model_facts
from pwa_pipeline.orchestration.assets import scores as score_assets
from pwa_pipeline.orchestration.definitions import build_definitions, partitions_of
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.mlflow_models import example_table
from pwa_pipeline.orchestration.partitions import (
    PartitionKey,
    all_keys,
    check_keys,
    runnable_keys,
)
from pwa_pipeline.orchestration.settings import PipelineSettings
from pwa_pipeline.orchestration.tracking import MLflowTracker

from .._results import holding, materialization

# every partitioned asset (what a sweep run materialises); the leaderboard has its own tests
ASSETS = [a for a in defs.assets if a.partitions_def is not None]


def _resources(folder, mlflow_template):
    db = folder / "mlflow.db"
    shutil.copy(mlflow_template, db)
    return {
        "io_manager": PartitionedFileIOManager(base_dir=str(folder / "storage")),
        "settings": PipelineSettings(cache_dir=str(folder / "cache"),
                                     hparams_path=str(BUNDLED_HPARAMS)),
        "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{db}"),
    }


@pytest.fixture()
def resources(tmp_path, mlflow_template):
    return _resources(tmp_path, mlflow_template)


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory, mlflow_template):
    """hure_vasak|paper materialised once for the tests that only read its results."""
    folder = tmp_path_factory.mktemp("paper_run")
    resources = _resources(folder, mlflow_template)
    result = dg.materialize(ASSETS, partition_key="hure_vasak|paper", resources=resources)
    return result, resources, folder


def _runs(resources, dataset):
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=resources["mlflow"].tracking_uri)
    exp = client.get_experiment_by_name(f"pwa-pipeline/{dataset}")
    return client, client.search_runs([exp.experiment_id])


def test_definitions_load():
    repo = defs.get_repository_def()
    keys = {k.to_user_string() for k in repo.asset_graph.get_all_asset_keys()}
    assert {"configuration", "raw_benchmark", "regressors", "local_models", "clusters",
            "sub_models", "svm_regions", "comparison"} <= keys
    assert {f"{m}_model" for m in METHODS} | {f"{m}_scores" for m in METHODS} <= keys
    assert repo.get_job("sweep") is not None
    assert repo.get_schedule_def("sweep_schedule").default_status == dg.DefaultScheduleStatus.STOPPED
    assert "config" not in defs.resources  # a name Dagster reserves for run config
    # one process per run: a process per step cost a UI-launched partition 88 s for 3 s
    assert repo.get_job("sweep").executor_def.name == "in_process"
    assert defs.executor.name == "in_process"


def test_schedule_requests_every_partition_once():
    schedule = defs.get_repository_def().get_schedule_def("sweep_schedule")
    ctx = dg.build_schedule_context(scheduled_execution_time=pd.Timestamp("2026-11-21T02:00"))
    requests = list(schedule(ctx))
    keys, skipped = runnable_keys(partitions_of(defs), defs.resources["settings"])
    assert sorted(r.partition_key for r in requests) == sorted(keys)
    # the robot's structure has values for the robot only: no other partition of it
    assert not [k for k in skipped if "|" in k]  # only data sets whose files are missing
    offered = all_keys(partitions_of(defs))
    assert "kuka_robot|robot" in offered and "hure_vasak|robot" not in offered
    assert len({r.run_key for r in requests}) == len(requests) == len(keys)
    assert "hure_vasak|paper" in keys


def test_partition_keys_parse_and_reject_typos():
    key = PartitionKey.parse("kuka_robot|paper")
    assert (key.dataset, key.hparams, str(key)) == ("kuka_robot", "paper", "kuka_robot|paper")
    for typo in ("kuka_robot", "a|b|c", "|paper"):
        with pytest.raises(ValueError, match=r"is not of the form 'dataset\|hparams'"):
            PartitionKey.parse(typo)
    with pytest.raises(ValueError, match=r"unknown partition 'kuka\|paper'; the partitions are "
                                         r"\['hure_vasak\|paper', "):
        check_keys(partitions_of(defs), ["hure_vasak|paper", "kuka|paper"])


def test_set_names_and_the_resource_read_the_same_file(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text("[only_one.hure_vasak]\n[only_one.kuka_robot]\n")
    custom = build_definitions(path)
    assert all_keys(partitions_of(custom)) == ["hure_vasak|only_one", "kuka_robot|only_one"]
    assert custom.resources["settings"].hparams_path == str(path)
    again = build_definitions(path, settings=PipelineSettings(hparams_path="elsewhere.toml"))
    assert again.resources["settings"].hparams_path == str(path)


def test_materialise_hure_vasak_paper(paper_run):
    result, resources, tmp_path = paper_run
    assert result.success
    model = result.asset_value("pwa_model")
    assert isinstance(model, PWARX) and model.thetas_.shape == (2, 4, 2)  # 2 of the 4 modes
    assert isinstance(result.asset_value("linear_arx_model"), LinearARX)
    assert isinstance(result.asset_value("subspace_model"), SubspaceSS)
    # the model asset is the one the core would fit: same sub-models as PWARX.fit
    cfg = result.asset_value("configuration")
    data = result.asset_value("raw_benchmark")
    direct = cfg.pwa.fit(data.u_train, data.y_train)
    np.testing.assert_array_equal(model.thetas_, direct.thetas_)
    table = result.asset_value("comparison")
    assert list(dict.fromkeys(table["method"])) == list(METHODS)
    assert len(table) == 3 * 2 * 3  # methods × modes × (2 outputs + mean)
    checks = {e.check_name: e.passed for e in result.get_asset_check_evaluations()}
    assert checks["finite_parameters"] and checks["at_least_one_sub_model"]
    assert checks["noise_share_below_limit"]
    # files written and read back
    stored = pd.read_parquet(tmp_path / "storage" / "comparison" / "hure_vasak" / "paper.parquet")
    pd.testing.assert_frame_equal(stored, table)
    assert (tmp_path / "storage" / "pwa_model" / "hure_vasak" / "paper.pkl").is_file()
    # MLflow: one run per method with params, metrics, tags and artifacts
    client, runs = _runs(resources, "hure_vasak")
    assert sorted(r.data.tags["method"] for r in runs) == sorted(METHODS)
    pwa = next(r for r in runs if r.data.tags["method"] == "pwa")
    given = cfg.pwa.get_params()  # the paper's values, from data/hparams.toml
    assert pwa.data.params["local_models__n_rho"] == str(given["local_models__n_rho"])
    assert pwa.data.params["clustering__eps"] == str(given["clustering__eps"])
    assert pwa.data.params["submodels"] == "ClusterCentres"
    assert pwa.data.tags["partition"] == "hure_vasak|paper"
    assert pwa.data.tags["dagster_run_id"] == result.run_id
    assert pwa.data.params["model/n_submodels"] == "2"
    free = table[(table.method == "pwa") & (table["mode"] == "free_run") & (table.output == "mean")]
    # headline metrics to 4 significant digits, per-output ones under their prefix
    assert pwa.data.metrics["free_run_nrmse"] == float(f"{free['nrmse'].iloc[0]:.4g}")
    assert {k for k in pwa.data.metrics if "/" not in k} == {
        "one_step_nrmse", "one_step_r2", "free_run_nrmse", "free_run_r2", "free_run_diverged",
        "one_step_outside_share", "free_run_outside_share", "fit_seconds"}
    assert {k.split("/")[0] for k in pwa.data.metrics if "/" in k} == {"per_output"}
    # what the model says of itself: params, never charts; booleans as true/false
    assert pwa.data.params["model/lyapunov_certified"] in ("true", "false")
    # each method's runs in a colour of their own in MLflow's UI
    colours = {r.data.tags["method"]: r.data.tags["mlflow.runColor"] for r in runs}
    assert colours == {m.name: m.colour for m in METHODS.values()} and \
        len(set(colours.values())) == len(METHODS)
    # the paper's linear baseline has no constant, and says so (its page, run, row)
    linear = next(r for r in runs if r.data.tags["method"] == "linear_arx")
    assert linear.data.params["model/constant"] == "no constant term"
    assert "No constant term." in linear.data.tags["mlflow.note.content"]
    assert materialization(result, "linear_arx_model").metadata["constant"].value == \
        "no constant term"
    assert set(result.asset_value("linear_arx_scores")["model"]) == {"no constant term"}
    assert "params.hparams" not in pwa.data.params and "dataset" not in pwa.data.params
    # the run spans the fit it scores, and says what it is
    fit = materialization(result, "pwa_model").metadata["fit_seconds"].value
    assert (pwa.info.end_time - pwa.info.start_time) / 1000 >= fit
    assert pwa.data.tags["mlflow.note.content"].startswith(
        "The pwa model of data set hure_vasak, hyper-parameter set paper. Held-out one-step")
    assert {a.path for a in client.list_artifacts(pwa.info.run_id)} == {
        "parameter_matrices.json", "scores.csv", "prediction.png", "control"}
    # the state-space model: its files, and the same JSON beside the registered model
    exported = result.asset_value("control_model").state_space
    shown = materialization(result, "control_model").metadata
    stored = Path(shown["json"].value)
    assert stored.parent == tmp_path / "exports" / "hure_vasak" / "paper"
    assert PWAStateSpace.from_json(stored).to_json() == exported.to_json()
    assert Path(shown["mpt3_script"].value).read_text() == exported.to_mpt3()
    logged = Path(mlflow.artifacts.download_artifacts(
        run_id=pwa.info.run_id, artifact_path="control/pwa_state_space.json",
        tracking_uri=resources["mlflow"].uri()))
    assert logged.read_text() == stored.read_text()
    assert pwa.data.params["model/control_modes"] == str(exported.n_modes) and \
        exported.n_modes == shown["n_modes"].value
    assert shown["regions"].value.startswith("![hure_vasak | set paper | PWA")
    meta = materialization(result, "pwa_scores").metadata
    assert meta["mlflow_run_id"].value == pwa.info.run_id
    # the prediction figure is rendered once: the PNG in MLflow is the one on the asset page
    png = Path(mlflow.artifacts.download_artifacts(run_id=pwa.info.run_id,
                                                   artifact_path="prediction.png",
                                                   tracking_uri=resources["mlflow"].uri()))
    inline = meta["prediction"].value.split("base64,", 1)[1].rstrip(")")
    assert png.read_bytes().startswith(b"\x89PNG") and \
        png.read_bytes() == base64.b64decode(inline)
    # the link opens MLflow 3.17's UI in its model-training view (the browser test follows it)
    assert meta["mlflow_run"].value == (f"http://127.0.0.1:5000/#/experiments/"
                                        f"{pwa.info.experiment_id}/runs/{pwa.info.run_id}"
                                        "?workflowType=machine_learning")
    experiment = client.get_experiment(pwa.info.experiment_id)
    assert experiment.tags["mlflow.experimentKind"] == "custom_model_development"
    # numbers on the asset pages carry 4 significant digits; checks name their partition
    eps = materialization(result, "clusters").metadata["eps"].value
    assert eps == float(f"{eps:.4g}")
    evaluations = result.get_asset_check_evaluations()
    assert {e.metadata["partition"].value for e in evaluations} == {"hure_vasak|paper"}
    assert all(e.description.startswith("partition hure_vasak|paper: ") for e in evaluations)
    noise = next(e for e in evaluations if e.check_name == "noise_share_below_limit")
    assert noise.description == (f"partition hure_vasak|paper: noise share "
                                 f"{model.steps_['clustering'].noise_share_:.1%} (limit 90%)")
    # figures on the asset pages, as Markdown with an inline PNG
    for asset, key in (("pwa_scores", "prediction"), ("clusters", "local models by cluster"),
                       ("pwa_model", "regions"),
                       ("pwa_model", "switching (first held-out experiment)")):
        text = materialization(result, asset).metadata[key].value
        assert text.startswith("![") and "(data:image/png;base64," in text
    sub = next(r for r in runs if r.data.tags["method"] == "subspace")
    assert sub.data.params["order"] == "2" and sub.data.params["warmup"] == "10"


def test_resolved_parameters_reach_mlflow_and_the_asset_page(resources):
    result = dg.materialize(ASSETS, partition_key="hure_vasak|default", resources=resources,
                            selection=dg.AssetSelection.assets("pwa_scores").upstream())
    model = result.asset_value("pwa_model")
    resolved = model.resolved_params()
    assert resolved["local_models__n_rho"] == 12 and resolved["clustering__min_pts"] == 8
    _, runs = _runs(resources, "hure_vasak")
    params = next(r for r in runs if r.data.tags["method"] == "pwa").data.params
    assert params["local_models__n_rho"] == "12" and params["clustering__min_pts"] == "8"
    assert float(params["clustering__eps"]) == pytest.approx(model.steps_["clustering"].eps_)
    page = materialization(result, "pwa_model").metadata
    table = page["resolved parameters"].value
    cells = dict(tuple(c.strip() for c in row.strip("|").split("|"))
                 for row in table.splitlines()[2:])
    assert cells["local_models__n_rho"] == "12" and "clustering__eps" in cells
    assert page["fit_seconds"].value > 0


def test_local_models_are_reused_when_only_eps_changes(resources, tmp_path):
    path = tmp_path / "eps.toml"
    path.write_text("".join(f"[eps_{i}.hure_vasak]\npreset = \"paper\"\nna = 1\nnb = 1\n"
                            f"local_models.n_rho = 12\nclustering.eps = {eps}\n"
                            f"clustering.min_pts = 8\n" for i, eps in enumerate((0.1, 0.3))))
    sweep = build_definitions(path)
    steps = ["configuration", "raw_benchmark", "regressors", "local_models", "clusters"]
    resources["settings"] = resources["settings"].with_files(path, tmp_path / "datasets.json")
    runs = [dg.materialize(list(sweep.assets), selection=steps,
                           partition_key=f"hure_vasak|eps_{i}", resources=resources)
            for i in (0, 1)]
    meta = [materialization(r, "local_models").metadata for r in runs]
    assert not meta[0]["from_cache"].value and meta[1]["from_cache"].value
    clusters = [r.asset_value("clusters") for r in runs]
    assert [c.eps_ for c in clusters] == [0.1, 0.3]  # the later step did see each set
    assert not np.array_equal(clusters[0].labels_, clusters[1].labels_)
    local = [r.asset_value("local_models") for r in runs]
    np.testing.assert_array_equal(local[0].theta_, local[1].theta_)


def _two_eps_sets(resources, tmp_path, *assets: str) -> list:
    """The identification assets up to the clusters and ``assets``, materialised for two
    default sets of hure_vasak that differ only in ε (0.22, 0.25; their clusterings differ,
    their sub-models and regions do not)."""
    path = tmp_path / "eps.toml"
    path.write_text("".join(f"[eps_{i}.hure_vasak]\npreset = \"default\"\nna = 1\nnb = 1\n"
                            f"clustering.eps = {eps}\n" for i, eps in enumerate((0.22, 0.25))))
    sweep = build_definitions(path)
    steps = ["configuration", "raw_benchmark", "regressors", "local_models", "clusters",
             *assets]
    resources["settings"] = resources["settings"].with_files(path, tmp_path / "datasets.json")
    return [dg.materialize(list(sweep.assets), selection=steps,
                           partition_key=f"hure_vasak|eps_{i}", resources=resources)
            for i in (0, 1)]


def test_sub_model_steps_are_reused_when_the_clusters_consolidate_alike(resources, tmp_path):
    """Two default sets that differ only in ε, whose clusterings (3 clusters, other noise
    rows) consolidate to the same sub-models: the second takes step 5's steps 2–4 from the
    signed cache, with the first's results; the stored steps hold no cache."""
    runs = _two_eps_sets(resources, tmp_path, "sub_models")
    meta = [materialization(r, "sub_models").metadata for r in runs]
    assert [m["from_cache"].value for m in meta] == [False, True]
    clusters = [r.asset_value("clusters") for r in runs]
    assert not np.array_equal(clusters[0].labels_, clusters[1].labels_)
    subs = [r.asset_value("sub_models") for r in runs]
    for name in ("thetas_", "labels_", "weights_"):
        np.testing.assert_array_equal(getattr(subs[0], name), getattr(subs[1], name))
    assert subs[1].memory is None and subs[0].n_submodels_ == 4
    cache = Path(resources["settings"].cache_root()) / "sub_models"
    assert len(list(cache.glob("*.pkl"))) == 1


def test_cached_scores_are_those_of_the_same_model_on_the_same_held_out_data(tmp_path):
    """The scores cache keys on the model's fingerprint and the data set's digest: the same
    model scored on held-out data changed in one sample (a user's edited test file) is
    scored again, and gives other scores."""
    import dataclasses

    from pwa_pipeline.datasets import load_dataset
    from pwa_pipeline.orchestration.caches import SignedMemory

    data = load_dataset("hure_vasak")
    y = data.y_test[0].copy()
    y[50:, 0] += 0.1
    edited = dataclasses.replace(data, y_test=[y])
    model = LinearARX(na=1, nb=1).fit(data.u_train, data.y_train)
    memory = SignedMemory(tmp_path, "scores")
    score = memory.cache(score_assets.scored, ignore=["model", "data"])
    first = score(model, data, 10, model_facts.prediction_key(model, data))
    again = score(model, data, 10, model_facts.prediction_key(model, data))
    other = score(model, edited, 10, model_facts.prediction_key(model, edited))
    assert (memory.hits, memory.misses) == (1, 2)
    pd.testing.assert_frame_equal(first.table, again.table)
    assert not np.allclose(first.table["nrmse"], other.table["nrmse"])


def test_sets_that_end_in_the_same_pwa_model_share_its_scores_figures_and_mlflow_model(
        resources, tmp_path):
    """Two default sets that differ only in ε and end in the same θ_i and regions (their
    clusterings differ): the second takes the PWA model's scores and the numbers of its
    figures from the cache (each set draws the figures, titled with its own name), and its
    MLflow run is linked to the model the first logged (one registered version);
    the models' prediction states are equal, their fingerprints too."""
    runs = _two_eps_sets(resources, tmp_path, "sub_models", "svm_regions",
                         "output_error_refinement", "pwa_model", "control_model",
                         "pwa_scores")

    def metadata(run, node: str, key: str):
        return materialization(run, node).metadata[key].value

    models = [r.asset_value("pwa_model") for r in runs]
    assert models[0].steps_["clustering"].eps_ != models[1].steps_["clustering"].eps_
    np.testing.assert_array_equal(models[0].thetas_, models[1].thetas_)
    assert joblib.hash([(g.regions, g.thetas) for g in models[0].groups_]) == \
        joblib.hash([(g.regions, g.thetas) for g in models[1].groups_])
    assert [metadata(r, "pwa_scores", "scores_from_cache") for r in runs] == [False, True]
    assert [metadata(r, "pwa_model", "figures_from_cache") for r in runs] == [False, True]
    for node, key in (("pwa_scores", "prediction"), ("pwa_model", "regions"),
                      ("pwa_model", "switching (first held-out experiment)")):
        texts = [metadata(r, node, key) for r in runs]
        assert texts[0] != texts[1]  # the same numbers, each set's own title
        for i, text in enumerate(texts):
            assert text.startswith(f"![hure_vasak | set eps_{i} | PWA "), (node, key)
    pd.testing.assert_frame_equal(runs[1].asset_value("pwa_scores"),
                                  runs[0].asset_value("pwa_scores"))
    client, tracked = _runs(resources, "hure_vasak")
    run_ids = {r.data.tags["hparams"]: r.info.run_id for r in tracked}
    assert {r.data.tags["model_run_id"] for r in tracked} == {run_ids["eps_0"]}
    assert [v.run_id for v in client.search_model_versions(
        "name = 'pwa-pipeline.hure_vasak.pwa'")] == [run_ids["eps_0"]]
    assert {r.data.params["clustering__eps"] for r in tracked} == {"0.22", "0.25"}
    assert len(list((tmp_path / "cache" / "model_figures").glob("*.pkl"))) == 1


def test_baselines_are_reused_across_sets_with_their_settings(resources, tmp_path,
                                                               monkeypatch):
    """Three sets of one data set: the second differs only in ε and takes both baselines, and
    their scores and figures, from the cache; the third's orders (na = nb = 2) change the
    linear ARX baseline, which is then fitted and scored, but not the subspace one. MLflow
    gets a run for every set and method, but each distinct model is logged and registered
    once. Without the cache, nothing is read or written."""
    path = tmp_path / "sets.toml"
    path.write_text("".join(f"[set_{i}.hure_vasak]\npreset = \"default\"\nna = {n}\nnb = {n}\n"
                            f"clustering.eps = {eps}\n"
                            for i, (n, eps) in enumerate(((1, 0.22), (1, 0.25), (2, 0.25)))))
    sweep = build_definitions(path)
    names = ("linear_arx_model", "subspace_model")
    scores = ("linear_arx_scores", "subspace_scores")
    steps = ["configuration", "raw_benchmark", *names, *scores]
    resources["settings"] = resources["settings"].with_files(path, tmp_path / "datasets.json")
    runs = [dg.materialize(list(sweep.assets), selection=steps,
                           partition_key=f"hure_vasak|set_{i}", resources=resources)
            for i in range(3)]

    def metadata(run, node: str, key: str):
        return materialization(run, node).metadata[key].value

    cached = {n: [metadata(r, n, "from_cache") for r in runs] for n in names}
    assert cached == {"linear_arx_model": [False, True, False],
                      "subspace_model": [False, True, True]}
    scored = {n: [metadata(r, n, "scores_from_cache") for r in runs] for n in scores}
    assert scored == {"linear_arx_scores": [False, True, False],
                      "subspace_scores": [False, True, True]}
    for n in names:  # the model the first set fitted, every fitted attribute equal
        first, reused = (vars(r.asset_value(n)) for r in runs[:2])
        assert reused.keys() == first.keys()
        for key in first:
            if key == "groups_":  # (region maps compare by content, not identity)
                for a, b in zip(first[key], reused[key], strict=True):
                    assert a.outputs == b.outputs and type(a.regions) is type(b.regions)
                    np.testing.assert_array_equal(a.thetas, b.thetas)
            else:
                np.testing.assert_equal(reused[key], first[key])
        assert runs[1].asset_value(n) is not runs[0].asset_value(n)
    for n in scores:
        pd.testing.assert_frame_equal(runs[1].asset_value(n), runs[0].asset_value(n))
        # the scores are the model's, the figure drawn by each set with its own name
        label = METHODS[n.removesuffix("_scores")].label
        for i in (0, 1):
            assert metadata(runs[i], n, "prediction").startswith(
                f"![hure_vasak | set set_{i} | {label} ")
    assert runs[2].asset_value("linear_arx_model").na == 2
    assert not runs[2].asset_value("linear_arx_scores").equals(
        runs[0].asset_value("linear_arx_scores"))
    for folder in ("baselines", "scores"):
        assert len(list((tmp_path / "cache" / folder).glob("*.pkl"))) == 3

    client, tracked = _runs(resources, "hure_vasak")
    run_ids = {(r.data.tags["method"], r.data.tags["hparams"]): r.info.run_id for r in tracked}
    logged_by = {(r.data.tags["method"], r.data.tags["hparams"]): r.data.tags["model_run_id"]
                 for r in tracked}
    assert logged_by == {
        ("linear_arx", "set_0"): run_ids["linear_arx", "set_0"],
        ("linear_arx", "set_1"): run_ids["linear_arx", "set_0"],
        ("linear_arx", "set_2"): run_ids["linear_arx", "set_2"],
        **{("subspace", f"set_{i}"): run_ids["subspace", "set_0"] for i in range(3)}}
    versions = {m: [v.run_id for v in client.search_model_versions(
        f"name = 'pwa-pipeline.hure_vasak.{m}'")] for m in ("linear_arx", "subspace")}
    assert sorted(versions["linear_arx"]) == sorted([run_ids["linear_arx", "set_0"],
                                                     run_ids["linear_arx", "set_2"]])
    assert versions["subspace"] == [run_ids["subspace", "set_0"]]
    reused = client.get_run(run_ids["subspace", "set_1"])
    first = client.get_run(run_ids["subspace", "set_0"])
    assert {k: reused.data.tags[k] for k in ("model_uri", "model_id")} == {
        k: first.data.tags[k] for k in ("model_uri", "model_id")}
    # the reusing run shows the model as its output, its training data, and who logged it
    assert [m.model_id for m in reused.outputs.model_outputs] == [first.data.tags["model_id"]]
    assert [(d.dataset.name, {t.key: t.value for t in d.tags}) for d in
            reused.inputs.dataset_inputs] == [("training", {"mlflow.data.context": "training"})]
    assert (reused.inputs.dataset_inputs[0].dataset.digest
            == first.inputs.dataset_inputs[0].dataset.digest)
    assert f"runs/{first.info.run_id}?" in reused.data.tags["mlflow.note.content"]
    reused = reused.data.tags
    data = runs[1].asset_value("raw_benchmark")
    table = example_table(data.u_test[0], data.y_test[0], data.u_names, data.y_names, 5, 30)
    np.testing.assert_allclose(  # the model its URI names is set_1's subspace model
        mlflow.pyfunc.load_model(reused["model_uri"]).predict(table).to_numpy()[5:],
        runs[1].asset_value("subspace_model").simulate(data.u_test[0][:30],
                                                           data.y_test[0][:5])[5:])

    # the scores' cache holds numbers only: changed figure code draws the figures again
    # from the cached fits and scores
    monkeypatch.setattr(images, "figures_fingerprint", lambda: "other figure code")
    run = dg.materialize(list(sweep.assets), selection=steps,
                         partition_key="hure_vasak|set_1", resources=resources)
    assert all(metadata(run, n, "from_cache") for n in names)
    assert all(metadata(run, n, "scores_from_cache") for n in scores)

    # a model deleted in the MLflow UI is logged again by the next run that scores it
    client.delete_logged_model(first.data.tags["model_id"])
    resources["settings"] = PipelineSettings(
        cache_dir=str(tmp_path / "uncached"), cache_baselines=False, cache_scores=False,
        hparams_path=str(path), datasets_path=str(tmp_path / "datasets.json"))
    run = dg.materialize(list(sweep.assets), selection=steps,
                         partition_key="hure_vasak|set_1", resources=resources)
    again = client.get_run(metadata(run, "subspace_scores", "mlflow_run_id")).data.tags
    assert again["model_run_id"] == metadata(run, "subspace_scores", "mlflow_run_id")
    assert again["model_id"] != first.data.tags["model_id"]
    assert not any(metadata(run, n, "from_cache") for n in names)
    assert not any(metadata(run, n, "scores_from_cache") for n in scores)
    pd.testing.assert_frame_equal(run.asset_value("subspace_scores"),
                                  runs[1].asset_value("subspace_scores"))
    assert not (tmp_path / "uncached").exists()


def test_unreachable_tracking_server_fails_clearly_and_keeps_assets(resources, tmp_path):
    resources["mlflow"] = MLflowTracker(tracking_uri="http://127.0.0.1:9", timeout_seconds=1)
    result = dg.materialize(ASSETS, partition_key="hure_vasak|paper", resources=resources,
                            raise_on_error=False)
    assert not result.success
    failures = [e for e in result.all_events if e.event_type_value == "STEP_FAILURE"]
    messages = " ".join(str(e.event_specific_data.error) for e in failures)
    assert "MLflow tracking server http://127.0.0.1:9 cannot be reached" in messages
    assert "already materialised are kept" in messages
    # the identification steps before tracking are materialised and stay on disk
    done = {e.asset_key.to_user_string() for e in result.get_asset_materialization_events()}
    assert {"regressors", "local_models", "clusters", "sub_models", "svm_regions",
            "pwa_model", "linear_arx_model", "subspace_model"} <= done
    assert (tmp_path / "storage" / "pwa_model" / "hure_vasak" / "paper.pkl").is_file()


def _materialize_set(tmp_path, mlflow_template, hparams: str, table: str):
    """Materialise ``hure_vasak|<hparams>`` of a hyper-parameter file holding only
    ``[<hparams>.hure_vasak]`` with the keys ``table``; returns (result, resources)."""
    path = tmp_path / "hparams.toml"
    path.write_text(f"[{hparams}.hure_vasak]\n{table}")
    custom = build_definitions(path)
    resources = _resources(tmp_path, mlflow_template)
    resources["settings"] = PipelineSettings(cache_dir=str(tmp_path / "cache"),
                                             hparams_path=str(path))
    result = dg.materialize([a for a in custom.assets if a.partitions_def is not None],
                            partition_key=f"hure_vasak|{hparams}", resources=resources)
    assert result.success
    return result, resources


def test_a_structured_set_is_fitted_whole_and_tracked(tmp_path, mlflow_template):
    result, resources = _materialize_set(
        tmp_path, mlflow_template, "moving",
        'na = 1\nnb = 1\naffine = true\nform = "velocity"\noutputs = "decoupled"\n'
        'scheduling.switch = "select"\nrefinement.max_iter = 3\n')
    model = result.asset_value("pwa_model")
    assert {o.structure for o in model.structure_fit_.outputs} <= {"linear", "offset", "all"}
    assert result.asset_value("output_error_refinement") is None  # refined in the fit
    meta = materialization(result, "output_error_refinement").metadata
    assert meta["reason"].value == "not fitted: the structured fit refines each output group itself"
    for asset in ("local_models", "clusters", "sub_models", "svm_regions"):  # not computed
        assert result.asset_value(asset) is None, asset
        meta = materialization(result, asset).metadata
        assert meta["reason"].value == ("not fitted: the model's regions are the signs of its "
                                        "scheduling variables")
    checks = {e.check_name: e for e in result.get_asset_check_evaluations()}
    assert {"noise_share_below_limit", "finite_parameters", "at_least_one_sub_model"} <= set(checks)
    assert all(checks[c].passed and "not_applicable" in checks[c].metadata
               for c in ("noise_share_below_limit", "finite_parameters"))
    linear = result.asset_value("linear_arx_model")
    assert (linear.form, linear.outputs) == ("velocity", "decoupled")
    client, runs = _runs(resources, "hure_vasak")
    pwa_run = next(r for r in runs if r.data.tags.get("method") == "pwa")
    assert pwa_run.data.params["structure_y1"] == model.structures_[0]
    assert pwa_run.data.params["scheduling__switch"] == "select"
    artifact = client.download_artifacts(pwa_run.info.run_id, "parameter_matrices.json",
                                         str(tmp_path))
    logged = json.loads(open(artifact).read())
    assert logged["structures"] == model.structures_ and len(logged["groups"]) == \
        len(model.groups_)


def test_the_auto_set_searches_the_structure_and_shows_what_it_tried(tmp_path,
                                                                     mlflow_template,
                                                                     monkeypatch):
    result, resources = _materialize_set(
        tmp_path, mlflow_template, "auto",
        'preset = "auto"\nna = 1\nnb = 1\nsearch.clustering = false\n'
        'search.max_variables = 1\nsearch.forms = ["level"]\nsearch.refinement = "none"\n')
    model = result.asset_value("pwa_model")
    report = model.structure_search_
    assert model.search.max_variables == 1 and not report.time_limited
    page_meta = materialization(result, "pwa_model").metadata
    page = page_meta["structure search"].value
    assert page.startswith(f"{report.n_candidates} candidates measured in ") \
        and "| chosen" in page
    # every row of a measured candidate counted: the linear and scheduled ones, not the
    # rows that only say a variable was kept or a candidate skipped
    table = report.table
    summary_rows = table.outcome.str.contains("lowers the held-out NRMSE") \
        | table.outcome.str.startswith("skipped")
    assert report.n_candidates == (table.stage.isin(["linear", "scheduled"])
                                   & ~summary_rows).sum() > 10
    client, runs = _runs(resources, "hure_vasak")
    pwa_run = next(r for r in runs if r.data.tags.get("method") == "pwa")
    assert pwa_run.data.params["search__max_variables"] == "1"
    assert pwa_run.data.params["model/search_linear"] == str(report.linear).lower()
    artifact = client.download_artifacts(pwa_run.info.run_id, "structure_search.csv",
                                         str(tmp_path))
    logged = pd.read_csv(artifact)
    assert len(logged) == len(report.table)
    assert list(logged.stage.unique()) == list(report.table.stage.unique())
    assert list(logged.columns[:4]) == ["stage", "outputs", "validation_nrmse", "outcome"]
    np.testing.assert_allclose(logged.validation_nrmse, report.table.validation_nrmse,
                               rtol=5e-4)
    assert float(pwa_run.data.params["model/search_linear_nrmse"]) == pytest.approx(
        report.linear_nrmse, rel=1e-3)
    assert pwa_run.data.params["model/search_candidates"] == str(report.n_candidates)
    assert pwa_run.data.params["model/search_budget_spent"] == "false"
    assert page_meta["structure chosen"].value == report.choice
    # what the model is, on its page and in its scores (which carry it to the leaderboard)
    assert list(page_meta)[0] == "model" and page_meta["model"].value == report.verdict
    assert report.verdict.startswith("linear kept" if report.linear else "switching")
    assert set(result.asset_value("pwa_scores")["model"]) == {report.verdict}
    assert set(result.asset_value("linear_arx_scores")["model"]) == {
        "affine: with a constant term"}
    assert page_meta["structure per output"].value.count("level (1, 1)") == 2
    # the steps the search did not run: their parameters left out, and why, on the page
    # and in MLflow (no n_rho, eps or min_pts of None)
    params = page_meta["resolved parameters"].value
    assert params.startswith("The paper's steps (local_models, clustering, submodels, "
                             "regions) did not run: the structure search kept no clustered "
                             "regions") and "| None " not in params.replace("search__", "")
    assert "na and nb are the largest orders it tried, form and outputs were not used" \
        in params.split("\n\n")[0]
    assert "clustering__eps" not in params and "search__max_variables" in params
    assert not {k for k in pwa_run.data.params if k.startswith("clustering")}
    # the true system compared on the search's larger regressor (na + 1 lags, a constant)
    assert page_meta["true_modes"].value == 4 and 0 < page_meta["region_accuracy"].value <= 1
    assert "ground_truth" not in page_meta and "max_param_error" in page_meta
    assert pwa_run.data.params["model/true_modes"] == "4"
    # the export works for a searched model too, and the registered model simulates as it
    assert result.asset_value("control_model").state_space.n_modes >= 1
    from pwa_pipeline.orchestration.mlflow_models import example_table

    data = result.asset_value("raw_benchmark")
    u, y = data.u_test[0][:200], data.y_test[0][:200]
    mlflow.set_tracking_uri(resources["mlflow"].tracking_uri)
    loaded = mlflow.pyfunc.load_model(pwa_run.data.tags["model_uri"]).predict(
        example_table(u, y, data.u_names, data.y_names, 10, rows=200)).to_numpy()
    np.testing.assert_allclose(loaded[10:], model.simulate(u, y[:10])[10:], rtol=1e-12)

    # a rerun with unchanged data and settings searches nothing: the model is reused, and
    # its page, the run's log and the command line's summary line say so
    from pwa_pipeline.orchestration.assets import identification
    from pwa_pipeline.orchestration.cli import _summary

    comparison = result.asset_value("comparison")
    assert page_meta["fit"].value == "fitted"
    assert "(reused" not in _summary("hure_vasak|auto", result, comparison, 1.0,
                                     dg.DagsterInstance.ephemeral())
    monkeypatch.setattr(identification, "fitted", lambda *args: pytest.fail("fitted again"))
    names = ["configuration", "raw_benchmark", "pwa_model", "pwa_scores"]
    custom = build_definitions(resources["settings"].hparams_path)
    instance = dg.DagsterInstance.ephemeral()
    # (a fit of an hour, as its run would be drawn were it fitted here)
    from dataclasses import replace

    from pwa_pipeline.orchestration.assets import scores
    from pwa_pipeline.orchestration.run_records import method_run

    monkeypatch.setattr(scores, "method_run", lambda *a, **k: replace(
        method_run(*a, **k), fit_seconds=3600.0))
    began = time.time()
    again = dg.materialize(holding(custom.assets, [*names, "control_model"]), selection=names,
                           partition_key="hure_vasak|auto", resources=resources,
                           instance=instance)
    # its MLflow run starts with the rerun, not an hour before it (the fit's time)
    rerun = client.get_run(materialization(again, "pwa_scores").metadata["mlflow_run_id"].value)
    assert rerun.info.start_time >= 1000 * began
    assert materialization(again, "pwa_model").metadata["fit"].value == \
        "reused: unchanged data and settings"
    assert any(e.user_message.startswith("PWA model reused: unchanged data and settings (")
               for e in instance.all_logs(again.run_id))
    # the log counts the candidates as the page does (measured, not the table's rows)
    assert any(e.user_message.startswith(f"structure search (reused, not run again): "
                                         f"{report.n_candidates} candidates measured in ")
               for e in instance.all_logs(again.run_id))
    np.testing.assert_array_equal(again.asset_value("pwa_model").thetas_, model.thetas_)
    assert _summary("hure_vasak|auto", again, comparison, 1.0, instance).startswith(
        f"hure_vasak|auto: {model.n_submodels_} PWA sub-model(s) (reused: unchanged data "
        f"and settings) — ")


def test_a_core_loggers_lines_reach_the_run_log_while_the_step_runs():
    from pwa_pipeline.orchestration.assets.identification import forwarded

    got = []

    class RunLog:
        def info(self, message):
            got.append(message)

    core = logging.getLogger("pwa_pipeline.pwa.some_step")
    with forwarded(core.name, RunLog()):
        core.info("stage %d of %d", 1, 3)
        core.debug("not at INFO")
    core.info("after the step")
    assert got == ["stage 1 of 3"]
    assert not core.handlers


def test_materialise_kuka_robot(resources, robot):
    result = dg.materialize(ASSETS, partition_key="kuka_robot|default", resources=resources)
    assert result.success
    data = result.asset_value("raw_benchmark")
    assert data.n_train == 39988 and len(data.u_test) == 6
    shown = materialization(result, "raw_benchmark").metadata
    assert shown["outputs"].value.startswith("q1 [deg], q2 [deg]")
    assert shown["inputs"].value.startswith("tau1 [N·m]")
    table = result.asset_value("comparison")
    one_step = table[(table["mode"] == "one_step") & (table.output == "mean")]
    assert (one_step["nrmse"] < 0.05).all()  # one-step prediction of 10 Hz positions is easy
    _, runs = _runs(resources, "kuka_robot")
    assert len(runs) == 3


def test_cli_lists_partitions_and_refuses_a_mistyped_key(capsys, tmp_path, monkeypatch):
    from pwa_pipeline.orchestration.cli import main

    assert main(["partitions"]) == 0
    assert capsys.readouterr().out.split() == all_keys(partitions_of(defs))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "home"))
    assert main(["run", "--partition", "hure_vasak|papr"]) == 2
    assert "error: unknown partition 'hure_vasak|papr'" in capsys.readouterr().err
    assert not (tmp_path / "home").exists()  # refused before any run


def test_a_failing_noise_check_stops_the_steps_after_clustering(resources, tmp_path):
    path = tmp_path / "noisy.toml"
    path.write_text("[noisy.hure_vasak]\npreset = \"paper\"\nna = 1\nnb = 1\n"
                    "local_models.n_rho = 18\nclustering.eps = 0.07\n"
                    "clustering.min_pts = 20\n")  # one cluster, 96 % noise
    noisy = build_definitions(path)
    resources["settings"] = resources["settings"].with_files(path, tmp_path / "datasets.json")
    result = dg.materialize(list(noisy.assets), partition_key="hure_vasak|noisy",
                            resources=resources, raise_on_error=False)
    check = next(e for e in result.get_asset_check_evaluations()
                 if e.check_name == "noise_share_below_limit")
    assert not check.passed and check.metadata["noise_share [hure_vasak|noisy]"].value > 0.9
    done = {e.asset_key.to_user_string() for e in result.get_asset_materialization_events()}
    assert "clusters" in done and not {"sub_models", "svm_regions", "pwa_model"} & done
    assert "linear_arx_model" in done  # what does not depend on the clusters still runs


def test_the_schedule_skips_data_sets_that_are_missing(monkeypatch, tmp_path):
    for variable in ("PWA_KUKA_DATA", "PWA_TANKS_DATA", "PWA_EMPS_DATA"):
        monkeypatch.setenv(variable, str(tmp_path / "nowhere"))
    schedule = defs.get_repository_def().get_schedule_def("sweep_schedule")
    ctx = dg.build_schedule_context(scheduled_execution_time=pd.Timestamp("2026-11-21T02:00"))
    requests = schedule(ctx)
    keys = [r.partition_key for r in requests]
    assert keys and all(k.startswith("hure_vasak|") for k in keys)
    # every set but robot, which has values for the robot only
    assert sorted(keys) == sorted(k for k in all_keys(partitions_of(defs))
                                  if k.startswith("hure_vasak|") and k != "hure_vasak|robot")


def test_registered_models_load_in_another_process_and_simulate_the_same(paper_run, tmp_path):
    import json
    import subprocess
    import sys

    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.mlflow_models import example_table

    result, resources, _ = paper_run
    uri = resources["mlflow"].tracking_uri
    client = MlflowClient(tracking_uri=uri)
    names = sorted(m.name for m in client.search_registered_models())
    assert names == [f"pwa-pipeline.hure_vasak.{m}" for m in sorted(METHODS)]
    for name in names:  # the set's alias, whichever set ran last
        assert "paper" in client.get_registered_model(name).aliases
    data = result.asset_value("raw_benchmark")
    u, y = data.u_test[0][500:700], data.y_test[0][500:700]  # not the logged example
    table = example_table(u, y, data.u_names, data.y_names, 10, rows=200)
    table.to_parquet(tmp_path / "input.parquet")
    script = (
        "import sys, json, mlflow, pandas as pd\n"
        f"mlflow.set_tracking_uri({uri!r})\n"
        "m = mlflow.pyfunc.load_model('models:/pwa-pipeline.hure_vasak.pwa@paper')\n"
        f"out = m.predict(pd.read_parquet({str(tmp_path / 'input.parquet')!r}))\n"
        "print(json.dumps(out.to_numpy().tolist()))\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    loaded = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    direct = result.asset_value("pwa_model").simulate(u, y[:10])
    np.testing.assert_allclose(loaded, direct, rtol=1e-12)
    # the run has a signature, an input example, and its training data as a dataset
    run_id = materialization(result, "pwa_scores").metadata[
        "mlflow_run_id"].value
    run = client.get_run(run_id)
    assert [d.dataset.name for d in run.inputs.dataset_inputs] == ["training"]
    model_info = mlflow_model_info(uri, run_id)
    assert model_info.signature.inputs.input_names() == data.u_names + data.y_names


def mlflow_model_info(uri, run_id):
    import mlflow

    mlflow.set_tracking_uri(uri)
    return mlflow.models.get_model_info(f"runs:/{run_id}/model")


class _Diverging:
    """Predicts the measured outputs plus a small error; its free run follows them too
    until sample ``at`` of experiment 1, where output 2 grows without bound."""

    def __init__(self, ys, at):
        self.ys, self.at = ys, at

    def predict(self, u, y, n_init=None):
        return [yy + 0.01 for yy in y]

    def simulate(self, u, y_init):
        runs = [yy + 0.02 for yy in self.ys]
        runs[1][self.at:, 1] = 1e3 * np.exp(np.arange(len(runs[1]) - self.at))
        return runs


def test_a_diverged_free_run_logs_where_it_diverged_and_no_score():
    from pwa_pipeline.orchestration.reporting import score_metrics
    from pwa_pipeline.scoring.evaluation import evaluate

    rng = np.random.default_rng(0)
    us = [rng.normal(size=(80, 1)) for _ in range(2)]
    ys = [rng.normal(size=(80, 2)) for _ in range(2)]
    ev = evaluate(_Diverging(ys, at=37), us, ys, warmup=10, output_names=["q1", "q2"])
    assert ev.diverged() and (ev.onset.experiment, ev.onset.sample) == (1, 37)
    # before it: all of experiment 0 and 27 scored samples of experiment 1, error 0.02
    scale = np.vstack([y[10:] for y in ys]).std(axis=0)
    assert ev.onset.nrmse_before == pytest.approx(np.mean(0.02 / scale))
    m = score_metrics(ev)
    assert m["free_run_diverged"] == 1 and m["free_run_divergence_sample"] == 37
    assert m["free_run_divergence_experiment"] == 1
    assert m["free_run_nrmse_before_divergence"] == float(f"{ev.onset.nrmse_before:.4g}")
    # no free-run number of the mean or of the diverged output; the other output keeps its
    assert not {"free_run_nrmse", "free_run_r2", "per_output/free_run_nrmse_q2"} & m.keys()
    assert m["per_output/free_run_nrmse_q1"] == float(f"{0.02 / scale[0]:.4g}")
    assert m["one_step_nrmse"] == float(f"{np.mean(0.01 / scale):.4g}")
    # a run that does not diverge logs its scores and no onset
    calm = score_metrics(evaluate(_Diverging(ys, at=80), us, ys, warmup=10))
    assert calm["free_run_diverged"] == 0 and "free_run_nrmse" in calm
    assert not any("divergence" in k for k in calm)


def test_a_diverged_run_is_shown_one_way_on_every_page():
    """Dagster's scores and comparison pages, the check, the MLflow run's tags and
    description all show a diverged free run as the leaderboard does: ≥ 10 (diverged)."""
    from types import SimpleNamespace

    from pwa_pipeline.orchestration.checks import comparison_results
    from pwa_pipeline.orchestration.reporting import (
        diverged_tags,
        mean_scores_markdown,
        nrmse_summary,
    )
    from pwa_pipeline.orchestration.run_records import method_run
    from pwa_pipeline.scoring.evaluation import evaluate

    class Fitted(_Diverging):
        def resolved_params(self):
            return {}

    rng = np.random.default_rng(0)
    us = [rng.normal(size=(80, 1)) for _ in range(2)]
    ys = [rng.normal(size=(80, 2)) for _ in range(2)]
    ev = evaluate(Fitted(ys, at=37), us, ys, warmup=10, output_names=["q1", "q2"])
    calm = evaluate(Fitted(ys, at=80), us, ys, warmup=10, output_names=["q1", "q2"])
    assert ev.mean("free_run") > 1e15  # the number no page shows
    shown = nrmse_summary(ev.table)  # the scores page
    assert shown["nrmse free_run mean"] == shown["nrmse free_run q2"] == "≥ 10 (diverged)"
    assert isinstance(shown["nrmse free_run q1"], float)
    table = pd.concat([ev.table.assign(method="pwa"), calm.table.assign(method="linear_arx")])
    page = mean_scores_markdown(table)  # the comparison page
    pwa_line = next(line for line in page.splitlines() if line.startswith("| pwa"))
    assert "≥ 10 (diverged)" in pwa_line and "≤ -99 (diverged)" in pwa_line
    assert "e+" not in page and "diverged" not in page.replace(pwa_line, "")
    (check,) = comparison_results(table, "sim|paper")
    assert not check.passed and check.description == (
        f"partition sim|paper: FAILED: free-run NRMSE of PWA ≥ 10 (diverged), of linear "
        f"ARX {calm.mean('free_run'):.4g}")
    # the check's numbers keyed by partition (a plot each), a diverged score as text
    assert check.metadata["pwa_free_run_nrmse [sim|paper]"].value == "≥ 10 (diverged)"
    assert check.metadata["linear_free_run_nrmse [sim|paper]"].value == float(
        f"{calm.mean('free_run'):.4g}")
    assert check.metadata["partition"].value == "sim|paper"
    assert not {key for key in check.metadata if key.endswith("nrmse")}
    record = method_run(SimpleNamespace(dataset="sim", hparams="paper", warmup=10), "pwa",
                        Fitted(ys, at=37), ev, SimpleNamespace(convention=None))  # MLflow
    assert record.tags == {"free_run_nrmse": "≥ 10 (diverged)",
                           "free_run_r2": "≤ -99 (diverged)",
                           "mlflow.runColor": METHODS["pwa"].colour}
    assert "free-run NRMSE ≥ 10 (diverged) from sample 37 of held-out experiment 1" \
        in record.description
    assert diverged_tags(calm) == {}
    # the command line's summary line, with what a searched model is
    from pwa_pipeline.orchestration.cli import _summary

    searched = SimpleNamespace(n_submodels_=1, structure_search_=SimpleNamespace(
        verdict="linear kept (no switching structure beat it held out)"))
    run = SimpleNamespace(asset_value=lambda name: searched, run_id="r")  # a model fitted
    line = _summary("sim|auto", run, table, 1.0, dg.DagsterInstance.ephemeral())
    assert line == (f"sim|auto: 1 PWA sub-model(s) — linear kept (no switching structure "
                    f"beat it held out); free-run NRMSE pwa ≥ 10 (diverged), linear_arx "
                    f"{calm.mean('free_run'):.4g} (1.0 s)")


def test_registered_model_versions_say_where_they_come_from(paper_run):
    from mlflow.tracking import MlflowClient

    result, resources, _ = paper_run
    client, runs = _runs(resources, "hure_vasak")
    by_method = {r.data.tags["method"]: r for r in runs}
    registry = MlflowClient(tracking_uri=resources["mlflow"].tracking_uri)
    for method in METHODS:
        [version] = registry.search_model_versions(f"name = 'pwa-pipeline.hure_vasak.{method}'")
        run = by_method[method]
        assert {k: version.tags[k] for k in ("dataset", "hparams", "method", "mlflow_run_id",
                                             "dagster_run_id", "partition")} == {
            "dataset": "hure_vasak", "hparams": "paper", "method": method,
            "mlflow_run_id": run.info.run_id, "dagster_run_id": result.run_id,
            "partition": "hure_vasak|paper"}
        assert "mlflow.runColor" in run.data.tags and "mlflow.runColor" not in version.tags
        free = run.data.metrics["free_run_nrmse"]
        assert version.description.startswith(
            f"The {method} model of data set hure_vasak, hyper-parameter set paper.")
        assert f"free-run NRMSE {free:.4g}" in version.description
        # to 4 significant digits, where MLflow's tables show 2 decimals (0.0027 as 0.00)
        assert f"free-run R² {run.data.metrics['free_run_r2']:.4g}" in version.description
    assert "2 sub-model(s)." in registry.search_model_versions(
        "name = 'pwa-pipeline.hure_vasak.pwa'")[0].description
