"""Temporary UI walk of sweep_dask taking turns (to be deleted)."""
import json
import os
import time
from pathlib import Path

import pytest

from tests.test_compose_services import services  # noqa: F401

OUT = Path("/tmp/uiwalk")


@pytest.mark.skipif(not os.environ.get("UIWALK_HOLD"), reason="hold mode only")
def test_hold(services):  # noqa: F811
    OUT.mkdir(exist_ok=True)
    (OUT / "info.json").write_text(json.dumps({"env": services["env"], "web": services["web"],
                                               "folder": str(services["folder"])}))
    stop = OUT / "stop"
    t0 = time.time()
    while not stop.exists() and time.time() - t0 < 1500:
        time.sleep(1)
