"""Orchestration layer: Dagster assets, resources, checks and schedules, MLflow tracking.

Everything numerical is imported from the core (`pwa_pipeline`); nothing here computes.
"""
