"""Shared, seeded test data (built once per session)."""

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from pwa_pipeline import PWARX
from pwa_pipeline.datasets import load_kuka, make_hure_vasak
from pwa_pipeline.scoring.metrics import match_submodels

#: Set (to anything non-empty) to turn the skips of tests that need a system package (Debian's
#: chromium, PostgreSQL) into failures: ``.ci/run`` installs them and sets it.
REQUIRE_SYSTEM = "PWA_REQUIRE_SYSTEM_TESTS"


@pytest.fixture(scope="session")
def system_package():
    """``check(what, problem)``: nothing when ``problem`` is None; else skip the test saying
    what is missing and how to get it, or fail where ``$PWA_REQUIRE_SYSTEM_TESTS`` is set."""

    def check(what: str, problem: str | None) -> None:
        if problem is None:
            return
        message = (f"{what}: {problem}. `bash .ci/run` installs it and runs the whole suite; "
                   f"{REQUIRE_SYSTEM}=1 makes this a failure instead of a skip")
        if os.environ.get(REQUIRE_SYSTEM):
            pytest.fail(message, pytrace=False)
        pytest.skip(message)

    return check


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true",
                     help="also run the tests marked slow (long checks the benchmarks repeat)")


def pytest_collection_modifyitems(config, items):
    """Every test under ``tests/system`` (real services: chromium, PostgreSQL, a cluster) is
    marked ``system``, so that ``-m "not system"`` runs the others alone; tests marked ``slow``
    are skipped unless ``--run-slow`` is given (a skip, not a ``-m`` filter, so that any ``-m``
    expression still leaves them out)."""
    system = Path(__file__).parent / "system"
    skip_slow = pytest.mark.skip(reason="slow: pass --run-slow to run it")
    for item in items:
        if system in Path(item.fspath).parents:
            item.add_marker(pytest.mark.system)
        if "slow" in item.keywords and not config.getoption("--run-slow"):
            item.add_marker(skip_slow)


def pytest_configure(config):
    """Keep the developer's own registered data sets out of the tests (set before any test
    module imports the definitions)."""
    os.environ["PWA_DATASETS"] = os.path.join(tempfile.mkdtemp(prefix="pwa-datasets-"),
                                              "datasets.json")


@pytest.fixture(scope="session")
def sim_clean():
    """The paper's section 5 system without noise (N = 2000)."""
    return make_hure_vasak(n_samples=2000, snr_db=None, seed=1)


@pytest.fixture(scope="session")
def sim_30db():
    """The paper's section 5 system at SNR 30 dB, N = 4000 (the paper's case)."""
    return make_hure_vasak(n_samples=4000, snr_db=30.0, seed=0)


@pytest.fixture(scope="session")
def default_30db(sim_30db):
    """The default PWARX fitted on :func:`sim_30db` (read-only: tests must not refit it)."""
    return PWARX(na=1, nb=1).fit(sim_30db.u_train[0], sim_30db.y_train[0])


@pytest.fixture(scope="session")
def robot():
    """The KUKA KR300 data, or a skip that says where it was looked for."""
    try:
        return load_kuka()
    except FileNotFoundError as exc:
        pytest.skip(f"KUKA robot data not available: {exc}")


def max_param_error(estimated: np.ndarray, true: np.ndarray) -> float:
    """Largest absolute entry error after matching estimated to true sub-models."""
    return float(np.nanmax(match_submodels(estimated, true)[1]))


@pytest.fixture(scope="session")
def mlflow_template(tmp_path_factory):
    """An MLflow sqlite store migrated once (it takes seconds), copied by each test."""
    from mlflow.tracking import MlflowClient

    path = tmp_path_factory.mktemp("mlflow") / "template.db"
    MlflowClient(tracking_uri=f"sqlite:///{path}").search_experiments()
    return path
