"""What the MLflow logging sends: the training dataset, the simulator, fingerprints."""

import shutil


def test_the_training_dataset_is_mlflows_with_a_digest_of_every_sample():
    import dataclasses

    import mlflow
    import numpy as np

    from pwa_pipeline.datasets import load_dataset
    from pwa_pipeline.orchestration.mlflow_models import training_dataset
    from pwa_pipeline.orchestration.reporting import training_table

    data = load_dataset("hure_vasak")
    logged = training_dataset(data)
    theirs = mlflow.data.from_pandas(training_table(data), name="training")
    assert logged.schema == theirs.schema and logged.profile == theirs.profile
    assert logged.name == "training" and logged.digest == data.digest[:20]
    y = [a.copy() for a in data.y_train]
    y[-1][-1, 0] += 1e-9  # the last sample, beyond the rows MLflow's own digest reads
    edited = training_dataset(dataclasses.replace(data, y_train=y))
    assert edited.digest != logged.digest
    np.testing.assert_array_equal(edited.df.iloc[-1, len(data.u_names)], y[-1][-1, 0])


def test_the_logged_simulator_keeps_what_simulation_needs_and_not_the_fit_record():
    import pickle

    import numpy as np

    from pwa_pipeline import PWARX, make_hure_vasak
    from pwa_pipeline.orchestration.mlflow_models import Simulator, example_table

    train = make_hure_vasak(n_samples=1500, snr_db=30, seed=0)
    test = make_hure_vasak(n_samples=300, snr_db=30, seed=1)
    model = PWARX.paper(1, 1, n_rho=18, eps=0.1, min_pts=20).fit(train.u_train[0], train.y_train[0])
    simulator = Simulator(model, train.u_names, train.y_names)
    data = pickle.dumps(simulator)
    back = pickle.loads(data)
    assert back.model.steps_ == {} and not hasattr(back.model, "timings_")
    assert "local_models" in model.steps_  # the fitted model itself is left whole
    table = example_table(test.u_train[0], test.y_train[0], train.u_names, train.y_names, 10, rows=300)
    np.testing.assert_array_equal(back.predict(None, table).to_numpy(),
                                  simulator.predict(None, table).to_numpy())
    assert len(data) < 0.1 * len(pickle.dumps(model))


def test_a_model_logged_by_a_run_purged_since_is_linked_all_the_same(
        tmp_path, mlflow_template, monkeypatch):
    """Two runs of one fitted model: the second links the model the first logged; with the
    first run gone from the store (``mlflow gc``), its description says so instead of
    linking it, and the run is still logged."""
    import mlflow
    from mlflow.exceptions import MlflowException
    from mlflow.tracking import MlflowClient

    from pwa_pipeline import LinearARX, make_hure_vasak
    from pwa_pipeline.orchestration.mlflow_models import (
        ModelToLog,
        Simulator,
        example_table,
    )
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    data = make_hure_vasak(n_samples=300, snr_db=30, seed=0)
    model = LinearARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
    table = example_table(data.u_train[0], data.y_train[0], data.u_names, data.y_names, 5)
    to_log = ModelToLog(Simulator(model, data.u_names, data.y_names), table,
                        mlflow.data.from_pandas(table, name="training"))

    def log(hparams: str) -> str:
        return tracker.log_run(dataset="d", hparams=hparams, method="linear_arx", params={},
                               metrics={}, tags={}, artifacts={}, model=to_log).run_id

    first = log("a")
    real_get_run = MlflowClient.get_run

    def purged(self, run_id):
        if run_id == first:
            raise MlflowException(f"Run '{run_id}' not found")
        return real_get_run(self, run_id)

    monkeypatch.setattr(MlflowClient, "get_run", purged)
    second = real_get_run(tracker.client(), log("b")).data.tags
    assert second["model_run_id"] == first
    assert f"{first} (no longer in the store)" in second["mlflow.note.content"]
    assert second["model_uri"] in second["mlflow.note.content"]


def test_models_that_predict_alike_share_a_fingerprint_and_others_do_not(default_30db, sim_30db):
    """A PWARX's fingerprint ignores the record of its fit and its unfitted steps (what
    ``predict`` and ``simulate`` do not read: a copy without them simulates the same), and
    sees its θ_i and its column names."""
    import copy

    import numpy as np

    from pwa_pipeline.orchestration.mlflow_models import predictor_fingerprint, without_fit_record
    from pwa_pipeline.pwa.steps.clustering import DBSCANClustering

    model, names = default_30db, (sim_30db.u_names, sim_30db.y_names)
    other = copy.deepcopy(model).set_params(clustering=DBSCANClustering(eps=0.3),
                                            local_models=None)
    other.timings_ = {"local_models": 99.0}
    stripped = without_fit_record(other)
    assert not any(g.steps for g in stripped.groups_) and not hasattr(stripped, "timings_")
    u, y = sim_30db.u_train[0][:300], sim_30db.y_train[0][:300]
    np.testing.assert_array_equal(stripped.simulate(u, y[:5]), model.simulate(u, y[:5]))
    np.testing.assert_array_equal(stripped.predict(u, y), model.predict(u, y))
    assert predictor_fingerprint(other, *names) == predictor_fingerprint(model, *names)
    nudged = copy.deepcopy(model)
    nudged.groups_[0].thetas[0, 0, 0] += 1e-12
    assert predictor_fingerprint(nudged, *names) != predictor_fingerprint(model, *names)
    assert predictor_fingerprint(model, names[0], ["a", "b"]) != \
        predictor_fingerprint(model, *names)


def test_the_training_table_stacks_the_experiments_and_labels_each_rows_experiment():
    from types import SimpleNamespace

    import numpy as np
    import pandas as pd

    from pwa_pipeline.orchestration.reporting import training_table

    rng = np.random.default_rng(0)
    lengths = (5, 3, 12)
    data = SimpleNamespace(u_train=[rng.normal(size=(n, 2)) for n in lengths],
                           y_train=[rng.normal(size=(n, 1)) for n in lengths],
                           u_names=["u1", "u2"], y_names=["y1"])
    table = training_table(data)
    assert list(table.columns) == ["u1", "u2", "y1", "experiment"]
    assert table["experiment"].tolist() == ["0"] * 5 + ["1"] * 3 + ["2"] * 12
    assert all(isinstance(v, str) for v in table["experiment"])
    np.testing.assert_array_equal(table[["u1", "u2"]].to_numpy(), np.concatenate(data.u_train))
    np.testing.assert_array_equal(table["y1"].to_numpy(), np.concatenate(data.y_train)[:, 0])
    assert isinstance(table.index, pd.RangeIndex) and len(table) == sum(lengths)


def test_each_set_has_an_alias_on_its_registered_version_and_the_model_says_what_it_is(
        tmp_path, mlflow_template, capsys):
    """``models:/…/latest`` is whichever set ran last: each set's newest version carries the
    set's name as its alias (a linked model's too; a name MLflow reserves, or ``best``, as
    ``set-<name>``), ``best`` the version of lowest free-run NRMSE across the sets, and the
    registered model has a description and tags of its own."""
    import mlflow
    import numpy as np
    from mlflow.tracking import MlflowClient

    from pwa_pipeline import LinearARX, make_hure_vasak
    from pwa_pipeline.orchestration.mlflow_models import ModelToLog, Simulator, example_table
    from pwa_pipeline.orchestration.tracking import MLflowTracker

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    tracker = MLflowTracker(tracking_uri=uri)
    name = "pwa-pipeline.d.linear_arx"

    def to_log(seed: int) -> ModelToLog:
        data = make_hure_vasak(n_samples=300, snr_db=30, seed=seed)
        model = LinearARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
        table = example_table(data.u_train[0], data.y_train[0], data.u_names, data.y_names, 5)
        return ModelToLog(Simulator(model, data.u_names, data.y_names), table,
                          mlflow.data.from_pandas(table, name="training"))

    def log(hparams: str, model: ModelToLog, nrmse: float) -> str:
        return tracker.log_run(dataset="d", hparams=hparams, method="linear_arx", params={},
                               metrics={"free_run_nrmse": nrmse}, tags={}, artifacts={},
                               model=model).run_id

    first, second = to_log(0), to_log(1)
    client = MlflowClient(tracking_uri=uri)
    log("a", first, 0.3)
    assert client.get_registered_model(name).aliases == {"a": 1, "best": 1}
    run_b = log("b", first, 0.3)  # links the version a registered
    log("a", second, 0.2)  # a new version: a's alias moves to it, b's stays; it is best
    assert client.get_registered_model(name).aliases["best"] == 2
    log("latest", second, 0.2)  # a reserved alias name
    log("best", first, float("nan"))  # so is best; a score not logged is never best
    printed = capsys.readouterr()  # MLflow's fluent registration prints at every version
    assert "registered model" not in (printed.out + printed.err).lower()
    registered = client.get_registered_model(name)
    assert registered.aliases == {"a": 2, "b": 1, "set-latest": 2, "set-best": 1, "best": 2}
    assert registered.description.startswith("The linear_arx model of data set d, ")
    assert f"`models:/{name}@<set>`" in registered.description
    assert "`best` is the version of lowest held-out free-run NRMSE" in registered.description
    assert registered.tags == {"dataset": "d", "method": "linear_arx"}
    assert client.get_model_version_by_alias(name, "b").run_id == \
        client.get_run(run_b).data.tags["model_run_id"]
    before = mlflow.get_tracking_uri()
    mlflow.set_tracking_uri(uri)
    try:
        loaded = mlflow.pyfunc.load_model(f"models:/{name}@b")
    finally:
        mlflow.set_tracking_uri(before)
    np.testing.assert_array_equal(loaded.predict(first.input_example).to_numpy(),
                                  first.simulator.predict(None, first.input_example).to_numpy())
