"""Helpers shared by the benchmark scripts: result paths, timing, writing tables."""

import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from io import BytesIO
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


def _cpu_ticks() -> list[int]:
    """The machine's CPU time so far by kind (the first line of /proc/stat, Linux)."""
    return [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]


class MachineLoad:
    """How busy the machine was over a benchmark: the 1-minute load average at the start and
    the end, and the share of the CPU time the hypervisor gave to other machines (steal, the
    eighth column of /proc/stat's ``cpu`` line) while it ran. A virtual machine's steal
    slows every timing without showing in the load average."""

    def __init__(self):
        self.load_start, self._ticks = os.getloadavg()[0], _cpu_ticks()

    def summary(self) -> dict:
        """``{"start", "end", "steal_share"}`` from the start until now."""
        delta = [b - a for a, b in zip(self._ticks, _cpu_ticks(), strict=True)]
        return {"start": self.load_start, "end": os.getloadavg()[0],
                "steal_share": delta[7] / max(sum(delta), 1)}


def describe_load(load: dict) -> str:
    """A :meth:`MachineLoad.summary` in words."""
    return (f"1-minute load average {load['start']:.2f} at the start, {load['end']:.2f} at "
            f"the end, {load['steal_share']:.0%} of the CPU time stolen by the hypervisor")


class Timer:
    """Context manager measuring wall-clock seconds in ``.seconds``."""

    def __enter__(self):
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self._t0


def in_fresh_process(module: str, args: list[str], tmp: Path, tree: Path = ROOT,
                     env: dict[str, str] | None = None) -> dict:
    """Run ``python -m <module> --worker <args…> <tmp>/out.json`` in a new process, with the
    package of ``tree`` (a checkout or an unpacked commit) first on its path, the KUKA data
    where this checkout finds them and ``env`` added to its environment; returns the JSON the
    worker wrote."""
    out = tmp / "out.json"
    path = os.pathsep.join(filter(None, [str(tree), str(ROOT), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, **(env or {}), "PYTHONPATH": path}
    env.setdefault("PWA_KUKA_DATA", str(ROOT.parent / "shared" / "data" / "kuka-kr300"))
    # run from tmp: with -m, the working directory would come first on sys.path
    subprocess.run([sys.executable, "-m", module, "--worker", *args, str(out)], check=True,
                   env=env, cwd=tmp)
    return json.loads(out.read_text())


def previous_tree(commit: str, into: Path) -> Path | None:
    """The package at ``commit``, unpacked under ``into`` (None if git cannot give it)."""
    try:
        blob = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "pwa_pipeline",
                               "data"], check=True, capture_output=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        print(f"previous implementation unavailable: {exc}")
        return None
    with tarfile.open(fileobj=BytesIO(blob)) as tar:
        tar.extractall(into, filter="data")
    return into


def against_commit(module: str, args: list[str], commit: str, repeats: int,
                   this_env: Callable[[int, Path], dict[str, str]] | None = None,
                   report: Callable[[int, str, dict], None] | None = None
                   ) -> dict[str, list[dict]]:
    """``module``'s worker on ``args`` in fresh processes (:func:`in_fresh_process`), this
    checkout and the package at ``commit`` alternated, ``repeats`` times each: their results
    as ``{"this": [...], commit: [...]}``. ``this_env(repeat, tmp)`` adds environment
    variables to this checkout's process of each repeat; ``report(repeat, version, result)``
    is called after each. Exits when git cannot give ``commit``."""
    runs: dict[str, list[dict]] = {"this": [], commit: []}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        tree = previous_tree(commit, tmp / "tree")
        if tree is None:
            raise SystemExit(f"git cannot give commit {commit}")
        for r in range(repeats):
            for name, path in (("this", ROOT), (commit, tree)):
                env = this_env(r, tmp) if this_env is not None and name == "this" else None
                runs[name].append(in_fresh_process(module, args, tmp, path, env))
                if report is not None:
                    report(r, name, runs[name][-1])
    return runs
