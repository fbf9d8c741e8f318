"""Helpers shared by the benchmark scripts: result paths, timing, writing tables."""

import json
import time
from pathlib import Path

import pandas as pd

RESULTS = Path(__file__).resolve().parent / "results"


def write_table(df: pd.DataFrame, stem: str) -> None:
    """Write ``results/<stem>.csv`` and ``results/<stem>.md``."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    df.to_csv(RESULTS / f"{stem}.csv", index=False)
    (RESULTS / f"{stem}.md").write_text(df.to_markdown(index=False, floatfmt=".4g") + "\n")


def write_json(data: dict, stem: str) -> None:
    """Write ``results/<stem>.json``."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{stem}.json").write_text(json.dumps(data, indent=2, default=float) + "\n")


class Timer:
    """Context manager measuring wall-clock seconds in ``.seconds``."""

    def __enter__(self):
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self._t0
