"""The Dagster code location, importable as ``pwa_pipeline.definitions`` (``workspace.yaml``,
``dagster ... -m pwa_pipeline.definitions``); built in `pwa_pipeline.orchestration`."""

from .orchestration.definitions import defs

__all__ = ["defs"]
