"""What the MLflow logging sends, built cheaply (issue 12): the same as MLflow's own."""


def test_training_dataset_is_the_one_mlflow_builds_from_every_row():
    import mlflow

    from pwa_pipeline.datasets.registry import load_dataset
    from pwa_pipeline.orchestration.mlflow_models import _SCHEMA_ROWS, ModelToLog
    from pwa_pipeline.orchestration.reporting import training_table

    table = training_table(load_dataset("hure_vasak"))
    assert len(table) > 10 * _SCHEMA_ROWS
    logged = ModelToLog(simulator=None, input_example=None, training=table).dataset()
    full = mlflow.data.from_pandas(table, name="training")
    assert logged.schema == full.schema
    assert logged.to_dict() == full.to_dict()  # name, digest, source, schema, profile


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
