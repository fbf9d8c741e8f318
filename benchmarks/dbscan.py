"""DBSCAN on the robot's local models: pwa_pipeline.pwa.steps.dbscan against scikit-learn.

The embedding is the paper setting's (KUKA training record, na = nb = 2, n_rho = 61, exact
embedding of the local parameter matrices: 39,856 points in 144 dimensions, eps = 8,
MinPts = 22). Each fit runs in a fresh subprocess, alternating between the two methods so
that both see the same machine load; the subprocess reports its wall time and its peak
resident memory, VmHWM of /proc/self/status (Linux), with its value just before the fit
(Python, numpy, scikit-learn and the embedding) as the baseline. Not ru_maxrss: on Linux a
child's ru_maxrss, and so the parent's RUSAGE_CHILDREN, starts from the parent's resident
memory when it was spawned (here the ~550 MB of building the embedding). One more fit of
pwa_pipeline.pwa.steps.dbscan in this process gives the peak of its numpy allocations (tracemalloc)
and, under cProfile, the share of the float32 distance blocks. The labels are compared: same
core points, same partition of the core points, same noise, and how many border points got
the same cluster (scikit-learn gives a border point to the first cluster that reaches it,
pwa_pipeline.pwa.steps.dbscan to its nearest core point's cluster).

Writes results/dbscan.json and results/dbscan.md.
Usage: python -m benchmarks.dbscan [--repeats 3]
"""

import argparse
import cProfile
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import tracemalloc
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, Timer, write_json

METHODS = ("pwa_pipeline", "scikit-learn")


def embedding() -> tuple[np.ndarray, float, int, float]:
    """The paper setting's embedding of the robot's local models, ε, MinPts, local-model time."""
    from sklearn.base import clone

    from pwa_pipeline import load_kuka
    from pwa_pipeline._validation import as_experiments
    from pwa_pipeline.config import HParamsFile
    from pwa_pipeline.pwa.steps.embedding import exact_embedding
    from pwa_pipeline.regressors import build_regressors

    robot = load_kuka()
    pwa = HParamsFile().configuration("paper", "kuka_robot").pwa
    reg = build_regressors(as_experiments(robot.u_train, robot.y_train), pwa.na, pwa.nb,
                           pwa.affine)
    with Timer() as t:
        local = clone(pwa.step_objects()["local_models"]).fit(reg.phi, reg.target)
    return exact_embedding(local.theta_), pwa.clustering.eps, pwa.clustering.min_pts, t.seconds


def peak_rss_mb() -> float:
    """High-water mark of this process's resident memory, MB (VmHWM, Linux)."""
    line = next(s for s in Path("/proc/self/status").read_text().splitlines()
                if s.startswith("VmHWM:"))
    return int(line.split()[1]) / 1024


def worker(method: str, data: Path, out: Path, eps: float, min_pts: int) -> None:
    """One fit in this (fresh) process; labels, core mask, seconds and memory to ``out``."""
    from sklearn.cluster import DBSCAN

    from pwa_pipeline.pwa.steps.dbscan import _dbscan

    emb = np.load(data)
    before = peak_rss_mb()
    with Timer() as t:
        if method == "scikit-learn":
            fit = DBSCAN(eps=eps, min_samples=min_pts).fit(emb)
            labels, core = fit.labels_, np.zeros(len(emb), bool)
            core[fit.core_sample_indices_] = True
        else:
            labels, core = _dbscan(emb, eps, min_pts, None)
    np.savez(out, labels=labels, core=core, seconds=t.seconds, peak_mb=peak_rss_mb(),
             before_mb=before)


def agreement(ours: dict, theirs: dict, emb: np.ndarray, eps: float) -> dict:
    """Core points, partition of the core points, noise and border clusters compared.

    A border point may differ only where core points of two clusters lie within eps of it;
    ``border_differ_ambiguous`` counts the differing ones for which that holds.
    """
    core = theirs["core"]
    pairs = np.unique(np.c_[ours["labels"][core], theirs["labels"][core]], axis=0)
    one_to_one = len(pairs) == len(np.unique(pairs[:, 0])) == len(np.unique(pairs[:, 1]))
    mapping = dict(zip(pairs[:, 1], pairs[:, 0], strict=True)) if one_to_one else {}
    border = np.flatnonzero(~core & (theirs["labels"] >= 0))
    differ = [i for i in border if mapping.get(theirs["labels"][i]) != ours["labels"][i]]
    core_idx = np.flatnonzero(core)
    ambiguous = sum(
        len(np.unique(theirs["labels"][core_idx[np.linalg.norm(emb[core_idx] - emb[i], axis=1)
                                               <= eps]])) > 1 for i in differ)
    return {"same_core_points": bool(np.array_equal(ours["core"], core)),
            "same_partition_of_core_points": bool(one_to_one),
            "same_noise": bool(np.array_equal(ours["labels"] < 0, theirs["labels"] < 0)),
            "n_clusters": int(theirs["labels"].max() + 1),
            "n_core": int(core.sum()), "n_noise": int((theirs["labels"] < 0).sum()),
            "n_border": int(border.size), "border_same_cluster": int(border.size - len(differ)),
            "border_differ_ambiguous": int(ambiguous)}


def profile_ours(emb: np.ndarray, eps: float, min_pts: int) -> dict:
    """Peak of one fit's numpy allocations; seconds of one under cProfile, and in the blocks."""
    from pwa_pipeline.pwa.steps.dbscan import dbscan

    tracemalloc.start()
    dbscan(emb, eps, min_pts)
    allocated = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    prof = cProfile.Profile()
    prof.runcall(dbscan, emb, eps, min_pts)
    stats = pstats.Stats(prof).stats
    total = max(v[3] for k, v in stats.items() if k[2] == "dbscan")
    blocks = sum(v[3] for k, v in stats.items() if k[2] == "near")
    return {"tracemalloc_peak_mb": allocated, "profiled_seconds": total,
            "distance_blocks_seconds": blocks}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--worker", nargs=5, metavar=("METHOD", "DATA", "OUT", "EPS", "MINPTS"))
    args = parser.parse_args()
    if args.worker:
        method, data, out, eps, min_pts = args.worker
        worker(method, Path(data), Path(out), float(eps), int(min_pts))
        return
    load = os.getloadavg()
    emb, eps, min_pts, local_seconds = embedding()
    print(f"embedding {emb.shape}, eps = {eps}, min_pts = {min_pts}, "
          f"local models {local_seconds:.1f} s, load average {load[0]:.2f}")
    runs: dict[str, list[dict]] = {m: [] for m in METHODS}
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "emb.npy"
        np.save(data, emb)
        for rep in range(args.repeats):
            for method in METHODS:
                out = Path(tmp) / f"{method}_{rep}.npz"
                subprocess.run([sys.executable, "-m", "benchmarks.dbscan", "--worker", method,
                                str(data), str(out), str(eps), str(min_pts)], check=True)
                with np.load(out) as f:
                    runs[method].append({k: f[k] for k in f.files})
                print(f"{method:13s} {float(runs[method][-1]['seconds']):6.2f} s, peak "
                      f"{float(runs[method][-1]['peak_mb']):6.0f} MB")
    summary = {}
    for method, rs in runs.items():
        summary[method] = {
            "median_seconds": statistics.median(float(r["seconds"]) for r in rs),
            "seconds": [float(r["seconds"]) for r in rs],
            "peak_rss_mb": max(float(r["peak_mb"]) for r in rs),
            "rss_before_fit_mb": max(float(r["before_mb"]) for r in rs)}
    ours, theirs = summary["pwa_pipeline"], summary["scikit-learn"]
    ratio = theirs["median_seconds"] / ours["median_seconds"]
    agree = agreement(runs["pwa_pipeline"][0], runs["scikit-learn"][0], emb, eps)
    prof = profile_ours(emb, eps, min_pts)
    result = {"n_points": emb.shape[0], "dims": emb.shape[1], "eps": eps, "min_pts": min_pts,
              "load_average_at_start": list(load), "cpu_count": os.cpu_count(),
              "local_models_seconds": local_seconds, "speed_up": ratio,
              "methods": summary, "agreement": agree, "profile": prof}
    print(result)
    write_json(result, "dbscan")
    lines = [
        f"## DBSCAN on the robot's local models ({emb.shape[0]:,} points, {emb.shape[1]} "
        f"dimensions, eps = {eps:g}, MinPts = {min_pts})\n",
        "| method | median s | runs (s) | peak RSS MB | RSS before fit MB |",
        "|:--|--:|:--|--:|--:|",
        *(f"| {m} | {s['median_seconds']:.2f} | {', '.join(f'{v:.2f}' for v in s['seconds'])} "
          f"| {s['peak_rss_mb']:.0f} | {s['rss_before_fit_mb']:.0f} |"
          for m, s in summary.items()),
        "",
        f"Speed-up over scikit-learn in the same run: {ratio:.1f}×. Load average at start "
        f"{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} on {os.cpu_count()} cores; each fit "
        f"in a fresh process, methods alternating. Peak RSS is the process's VmHWM (Python, "
        f"numpy, scikit-learn and the 46 MB embedding included, as the column before the fit "
        f"shows); pwa_pipeline's numpy allocations peak at {prof['tracemalloc_peak_mb']:.0f} MB "
        f"(tracemalloc, one more fit).",
        "",
        f"Agreement: same core points {agree['same_core_points']}, same partition of the core "
        f"points {agree['same_partition_of_core_points']}, same noise {agree['same_noise']} "
        f"({agree['n_clusters']} clusters, {agree['n_core']} core points, {agree['n_noise']} "
        f"noise); {agree['border_same_cluster']} of {agree['n_border']} border points in "
        f"scikit-learn's cluster; {agree['border_differ_ambiguous']} of the others have core "
        f"points of two clusters within eps (either cluster is then DBSCAN's).",
        "",
        f"One profiled fit: {prof['profiled_seconds']:.2f} s, of which "
        f"{prof['distance_blocks_seconds']:.2f} s in the float32 distance blocks "
        f"(pwa_pipeline.pwa.steps.dbscan._Geometry.near). The local models of the same fit took "
        f"{local_seconds:.1f} s."]
    (RESULTS / "dbscan.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
