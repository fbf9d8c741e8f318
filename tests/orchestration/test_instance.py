"""The command line's Dagster instance."""

import os

from .._fork_pool import fork_pool


def _prepare(home):
    os.environ["DAGSTER_HOME"] = home
    from pwa_pipeline.orchestration.instance import prepare_instance

    prepare_instance().get_runs(limit=1)
    return "ok"


def test_instances_created_at_once_share_one_schema(tmp_path):
    import sqlite3

    for trial in range(2):  # without the lock 2 of 3 such trials broke the home
        home = tmp_path / f"home{trial}"
        with fork_pool(4) as pool:
            assert pool.map(_prepare, [str(home)] * 4) == ["ok"] * 4
        db = sqlite3.connect(home / "history" / "runs.db")
        assert db.execute("select count(*) from alembic_version").fetchone() == (1,)
        assert "nux:\n  enabled: false" in (home / "dagster.yaml").read_text()

