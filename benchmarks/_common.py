"""Helpers shared by the benchmark scripts: result paths, timing, writing tables."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = RESULTS.parents[1]


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


def in_fresh_process(module: str, args: list[str], tmp: Path, tree: Path = ROOT) -> dict:
    """Run ``python -m <module> --worker <args…> <tmp>/out.json`` in a new process, with the
    package of ``tree`` (a checkout or an unpacked commit) first on its path and the KUKA
    data where this checkout finds them; returns the JSON the worker wrote."""
    out = tmp / "out.json"
    path = os.pathsep.join(filter(None, [str(tree), str(ROOT), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path}
    env.setdefault("PWA_KUKA_DATA", str(ROOT.parent / "shared" / "data" / "kuka-kr300"))
    # run from tmp: with -m, the working directory would come first on sys.path
    subprocess.run([sys.executable, "-m", module, "--worker", *args, str(out)], check=True,
                   env=env, cwd=tmp)
    return json.loads(out.read_text())


def default_fit(fit: str):
    """The default estimator and training record of a fit named ``case:seed`` (a case of
    ``benchmarks.robustness`` at a seed) or ``robot`` (the default set on the KUKA training
    record): ``(estimator, u, y)``. Imports inside, so that a worker can pair this checkout's
    benchmarks with an earlier commit's package."""
    from sklearn.base import clone

    if fit == "robot":
        from pwa_pipeline import load_kuka
        from pwa_pipeline.config import HParamsFile

        robot = load_kuka()
        return (clone(HParamsFile().configuration("default", "kuka_robot").pwa),
                robot.u_train, robot.y_train)
    from benchmarks.robustness import CASES, paper_system, random_system
    from pwa_pipeline import PWARX

    name, seed = fit.split(":")
    case = CASES[name]
    system = (paper_system() if case.system is None
              else random_system(int(seed), **case.system, hold=case.hold))
    record = system.record(case.n, int(seed), case.snr_db, case.hold)
    return PWARX(na=system.na, nb=system.nb), record.u, record.y
