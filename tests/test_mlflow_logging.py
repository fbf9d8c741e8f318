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
