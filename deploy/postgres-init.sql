-- The second database of the shared PostgreSQL server (the first, dagster, is POSTGRES_DB):
-- MLflow's tracking store.
CREATE DATABASE mlflow;
