"""What the MLflow logging sends, built cheaply (issue 12): the same as MLflow's own."""

import contextlib
import shutil


def test_training_dataset_is_the_one_mlflow_builds_from_every_row():
    import mlflow

    from pwa_pipeline.datasets.registry import load_dataset
    from pwa_pipeline.orchestration.mlflow_models import _SCHEMA_ROWS, table_dataset
    from pwa_pipeline.orchestration.reporting import training_table

    table = training_table(load_dataset("hure_vasak"))
    assert len(table) > 10 * _SCHEMA_ROWS
    logged = table_dataset(table)
    full = mlflow.data.from_pandas(table, name="training")
    assert logged.schema == full.schema
    assert logged.to_dict() == full.to_dict()  # name, digest, source, schema, profile


def test_a_data_sets_training_dataset_is_built_once_and_again_for_other_data(monkeypatch):
    import dataclasses

    import numpy as np

    from pwa_pipeline.datasets.registry import load_dataset
    from pwa_pipeline.orchestration import mlflow_models
    from pwa_pipeline.orchestration.reporting import training_table

    built = []
    monkeypatch.setattr(mlflow_models, "training_table",
                        lambda data: built.append(data.name) or training_table(data))
    monkeypatch.setattr(mlflow_models, "_TRAINING_DATASETS", type(
        mlflow_models._TRAINING_DATASETS)())
    data = load_dataset("hure_vasak")
    first = mlflow_models.training_dataset(data)
    assert mlflow_models.training_dataset(data) is first and len(built) == 1
    assert first.to_dict() == mlflow_models.table_dataset(training_table(data)).to_dict()
    y = [a.copy() for a in data.y_train]
    y[0][0, 0] += 1e-9  # one sample of the training data
    edited = dataclasses.replace(data, y_train=y)
    other = mlflow_models.training_dataset(edited)
    assert len(built) == 2 and other.digest != first.digest
    np.testing.assert_array_equal(other.df.iloc[0, len(data.u_names)], y[0][0, 0])
    # the four most recently used are kept
    for k in range(2):
        mlflow_models.training_dataset(dataclasses.replace(data, name=f"copy{k}"))
    assert mlflow_models.training_dataset(data) is first and len(built) == 4
    for k in range(2, 6):  # four more: edited, copy0 and copy1 go, then data
        mlflow_models.training_dataset(dataclasses.replace(data, name=f"copy{k}"))
        assert (data.digest in mlflow_models._TRAINING_DATASETS) == (k < 5)
    assert mlflow_models.training_dataset(data) is not first and len(built) == 9


def test_the_logged_simulator_keeps_what_simulation_needs_and_not_the_fit_record():
    import pickle

    import numpy as np

    from pwa_pipeline import PWARX, make_hure_vasak
    from pwa_pipeline.orchestration.mlflow_models import Simulator, example_table

    train = make_hure_vasak(n_samples=1500, snr_db=30, seed=0)
    test = make_hure_vasak(n_samples=300, snr_db=30, seed=1)
    model = PWARX.paper(1, 1, n_rho=18, eps=0.1, min_pts=20).fit(train.u, train.y)
    simulator = Simulator(model, train.u_names, train.y_names)
    data = pickle.dumps(simulator)
    back = pickle.loads(data)
    assert not any(hasattr(back.model, a) for a in
                   ("local_models_", "clustering_", "submodels_", "labels_"))
    assert hasattr(model, "local_models_")  # the fitted model itself is left whole
    table = example_table(test.u, test.y, train.u_names, train.y_names, 10, rows=300)
    np.testing.assert_array_equal(back.predict(None, table).to_numpy(),
                                  simulator.predict(None, table).to_numpy())
    assert len(data) < 0.1 * len(pickle.dumps(model))


def test_a_model_logged_by_a_run_purged_since_is_linked_all_the_same(
        tmp_path, mlflow_template, monkeypatch):
    """Two runs of one fitted model: the second links the model the first logged; with the
    first run gone from the store (``mlflow gc``), its description says so instead of
    linking it, and the run is still logged."""
    from mlflow.exceptions import MlflowException
    from mlflow.tracking import MlflowClient

    from pwa_pipeline import LinearARX, make_hure_vasak
    from pwa_pipeline.orchestration.mlflow_models import (
        ModelToLog,
        Simulator,
        example_table,
        table_dataset,
    )
    from pwa_pipeline.orchestration.resources import MLflowTracker

    shutil.copy(mlflow_template, tmp_path / "mlflow.db")
    tracker = MLflowTracker(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    data = make_hure_vasak(n_samples=300, snr_db=30, seed=0)
    model = LinearARX(na=1, nb=1).fit(data.u, data.y)
    table = example_table(data.u, data.y, data.u_names, data.y_names, 5)
    to_log = ModelToLog(Simulator(model, data.u_names, data.y_names), table,
                        table_dataset(table))

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


def _journal_mode(db) -> str:
    import sqlite3

    with contextlib.closing(sqlite3.connect(db)) as conn:
        return conn.execute("PRAGMA journal_mode").fetchone()[0]


def test_the_embedded_store_logs_in_write_ahead_log_mode_unless_it_is_being_read(
        tmp_path, mlflow_template, monkeypatch):
    """The tracker puts a store in WAL mode when it first uses it; a store another process is
    reading at that moment keeps its mode, and runs are logged all the same."""
    import sqlite3

    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration import resources

    monkeypatch.setattr(resources, "WAL_WAIT_SECONDS", 0.1)
    for name, read in (("free.db", False), ("read.db", True)):
        db = tmp_path / name
        shutil.copy(mlflow_template, db)
        assert _journal_mode(db) == "delete"  # MLflow's own
        tracker = resources.MLflowTracker(tracking_uri=f"sqlite:///{db}")
        with contextlib.closing(sqlite3.connect(db, isolation_level=None)) as reader:
            if read:  # a read transaction: its shared lock bars the change of mode
                reader.execute("BEGIN")
                reader.execute("SELECT count(*) FROM experiments").fetchone()
            tracker.client()  # the store's first use in this process
            if read:
                reader.execute("COMMIT")
        run = tracker.log_run(dataset="d", hparams="s", method="pwa", params={},
                              metrics={"m": 1.0}, tags={}, artifacts={})
        assert _journal_mode(db) == ("delete" if read else "wal")
        stored = MlflowClient(tracking_uri=f"sqlite:///{db}").get_run(run.run_id)
        assert stored.info.status == "FINISHED" and stored.data.metrics == {"m": 1.0}


def test_the_digest_is_mlflows_for_text_numeric_and_other_columns():
    import numpy as np
    import pandas as pd
    from mlflow.data.digest_utils import compute_pandas_digest

    from pwa_pipeline.orchestration.mlflow_models import pandas_digest

    rng = np.random.default_rng(0)
    table = pd.DataFrame({"u1": rng.normal(size=12_000), "n": np.arange(12_000),
                          "flag": np.arange(12_000) % 2 == 0,
                          "experiment": [str(i % 3) for i in range(12_000)],
                          "text with a gap": ["a"] * 11_999 + [None],
                          "kind": pd.Categorical(["p", "q"] * 6_000),
                          "at": pd.Timestamp("2026-01-01")})
    digests = {pandas_digest(t): compute_pandas_digest(t)
               for t in (table, table.iloc[:, [3, 0]], table.tail(500), table.iloc[:, :3])}
    assert all(ours == theirs for ours, theirs in digests.items()) and len(digests) == 4


def test_models_that_predict_alike_share_a_fingerprint_and_others_do_not(default_30db, sim_30db):
    """A PWARX's fingerprint ignores the record of its fit and its unfitted steps (what
    ``predict`` and ``simulate`` do not read: a copy without them simulates the same), and
    sees its θ_i and its column names."""
    import copy

    import numpy as np

    from pwa_pipeline.orchestration.mlflow_models import predictor_fingerprint
    from pwa_pipeline.pwa import PWARX
    from pwa_pipeline.pwa.clustering import DBSCANClustering

    model, names = default_30db, (sim_30db.u_names, sim_30db.y_names)
    other = copy.deepcopy(model).set_params(clustering=DBSCANClustering(eps=0.3),
                                            local_models=None)
    other.timings_ = {"local_models": 99.0}
    stripped = copy.copy(other)
    for name in PWARX.FIT_RECORD + PWARX.FIT_PARAMS:
        stripped.__dict__.pop(name, None)
    assert set(model.prediction_state()) == set(vars(stripped))
    u, y = sim_30db.u[:300], sim_30db.y[:300]
    np.testing.assert_array_equal(stripped.simulate(u, y[:5]), model.simulate(u, y[:5]))
    np.testing.assert_array_equal(stripped.predict(u, y), model.predict(u, y))
    assert predictor_fingerprint(other, *names) == predictor_fingerprint(model, *names)
    nudged = copy.deepcopy(model)
    nudged.thetas_[0, 0, 0] += 1e-12
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
