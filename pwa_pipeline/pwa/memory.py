"""The memory a PWARX fit needs, estimated before it starts, and what the machine has.

`check_fit_memory` runs before the first step of a fit: a fit whose estimate exceeds
the memory available fails at once with a [`FitMemoryError`][pwa_pipeline.pwa.FitMemoryError] naming the
estimate and the setting to change, instead of being killed by the operating system half-way.
"""

import os
from pathlib import Path

from .steps.clustering import _DENSE
from .steps.local_models import _CHUNK
from .steps.neighbours import _BLOCK

_GiB = 2**30
_SLACK = 2**28
"""Added to every step: temporaries and memory the allocator keeps after earlier steps
(measured up to ~0.23 GiB above the counted arrays on the robot record)."""


class FitMemoryError(MemoryError):
    """A fit would need more memory than the machine has available."""


def available_memory() -> int | None:
    """Bytes this process can still allocate: ``MemAvailable`` of ``/proc/meminfo``, capped
    by the cgroup's limit minus its usage (containers, CI runners); None if unknown."""
    avail = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                avail = int(line.split()[1]) * 1024
    except OSError:
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            return None
    for limit_file, usage_file in (("memory.max", "memory.current"),
                                   ("memory/memory.limit_in_bytes",
                                    "memory/memory.usage_in_bytes")):
        try:
            limit = (Path("/sys/fs/cgroup") / limit_file).read_text().strip()
            usage = int((Path("/sys/fs/cgroup") / usage_file).read_text())
        except (OSError, ValueError):
            continue
        if limit.isdigit() and int(limit) < 2**60:
            avail = min(avail, max(int(limit) - usage, 0))
    return avail


def fit_memory(n: int, d: int, m: int, steps: dict) -> dict[str, int]:
    """Estimated peak bytes of each step of a fit on n regressor rows (d regressors, m
    outputs), beyond the regressors themselves; ``steps`` are the unfitted step objects by
    name ([`pwa_pipeline.pwa.estimator.PWARX.step_objects`][pwa_pipeline.PWARX.step_objects]).

    Counted: the arrays that grow with n (local sets, local models, candidate neighbour
    pairs, embeddings, distance blocks, residual tables, the SVM's copy of its rows), from
    their sizes in the code, plus 0.25 GiB for temporaries and what the allocator keeps. An
    estimate, meant to err high: ``benchmarks.scale`` compares it with measured peaks.
    """
    local, clustering = steps["local_models"], steps["clustering"]
    submodels, regions = steps["submodels"], steps["regions"]
    n_rho = min(getattr(local, "n_rho", None) or 3 * d, n)
    workers = len(os.sched_getaffinity(0))
    kept = n * (n_rho * 8 + d * m * 8 + m * 8)  # neighbours, θ_k, residual variances
    sets = n if getattr(local, "max_sets", None) is None else min(n, local.max_sets)
    if d > 12:  # blocked search: float32 copies and ~6·n_ρ candidates a searched row (12 B
        # each, 24 more while a block of them is selected), a tile's room per thread
        search = n * (d + 2) * 8 + sets * 6 * n_rho * 12 + (
            _BLOCK * 6 * n_rho * 24 + _BLOCK * _BLOCK * 24) * workers
    else:  # scikit-learn's tree: distances and indices of every searched row
        search = sets * n_rho * 16
    solve = workers * (_CHUNK * d * (d + m) * 8 * 3 + (n_rho + d) * (d + m) * 8)
    out = {"local_models": kept + max(search, solve)}

    n_c = n if getattr(clustering, "max_clustered", None) is None else min(
        n, clustering.max_clustered)
    width = d * m * (m if getattr(clustering, "embedding", "exact") == "literal" else 1)
    # a neighbourhood holds at most the n_c models clustered, however large MinPts is
    min_pts = min(getattr(clustering, "min_pts", None) or 2 * d, n_c)
    dbscan = n_c * (width * 8 * 4 + 64 * 8 * 2 + min_pts * 16) + 3 * 2**25
    counts = 0 if getattr(clustering, "eps", None) is not None else (  # the distances (8 B
        n_c * n_c * 9 if n_c * n_c <= _DENSE else 2**25)  # a pair, made in place; 1 B slack)
    out["clustering"] = kept + n * d * m * 8 + max(dbscan, counts)

    s = 30 if type(submodels).__name__ == "RefinedSubModels" else 0  # sub-models met at most
    refined = n if getattr(submodels, "max_rows", None) is None else min(n, submodels.max_rows)
    out["submodels"] = kept + s * refined * m * 8 * 3
    rows = n if getattr(regions, "max_rows", None) is None else min(n, regions.max_rows)
    out["regions"] = kept + rows * (d + 2) * 8 * 3
    return {step: size + _SLACK for step, size in out.items()}


_KNOB = {"local_models": "local_models__n_rho (smaller local sets), local_models__max_sets "
                        "(fewer local models) or the record's length",
         "clustering": "clustering__max_clustered (cluster a subset of the local models)",
         "submodels": "submodels__max_rows (refine the sub-models on a subset of the rows)",
         "regions": "regions__max_rows (fit the region SVM on a subset)"}


def check_fit_memory(n: int, d: int, m: int, steps: dict, base: int = 0) -> dict[str, int]:
    """Raise [`FitMemoryError`][pwa_pipeline.pwa.FitMemoryError] when the estimated peak (`fit_memory`, plus
    ``base`` bytes already needed, e.g. the regressors) exceeds `available_memory`.

    Returns the per-step estimates.
    """
    est = fit_memory(n, d, m, steps)
    avail = available_memory()
    step = max(est, key=est.get)
    need = base + est[step]
    if avail is not None and need > avail:
        raise FitMemoryError(
            f"this fit needs an estimated {need / _GiB:.2f} GiB (peak in the {step} step, "
            f"{n} regressor rows, d = {d}, m = {m}) but only {avail / _GiB:.2f} GiB are "
            f"available; lower {_KNOB[step]}, or free memory")
    return est
