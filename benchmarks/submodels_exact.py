"""Whether this checkout's default fit gives the sub-models of an earlier commit (the speed-ups
of the sub-model step must not change its results).

Each fit (cases of ``benchmarks.robustness`` at ``case:seed``, and ``robot``) runs in a fresh
process with this checkout's package and with the ``--against`` commit's; this checkout runs
with ``split_sweep_tol=0`` and ``settle_tol=0`` (the sweeps wait for no row to move, as before
those parameters), so everything else it changed must leave θ_i, the labels and the regions
as they were. Reported per fit: the number of sub-models of each, the largest |Δθ|, the rows
labelled differently, the largest |Δ| of the region hyperplanes; and the same of this
checkout's default (the stopping rules on) against the commit: where they fire. Exits with
status 1 when θ differs by more than 1e-9 or a label differs with the rules off. The default
reference, ba13a41, is the code before ``settle_tol``; against bf2d52f (before step 5's
memoised sweeps) step 6 has changed since: the labels of the three 20 dB fits at 5000–5002
were the same, θ_i and the regions not. Since step 3's compiled QR (local θ_k within 6e-10
relative of LAPACK's, ``benchmarks.local_solve``) one fit takes another path with the rules
off, ``paper-20dB:5002`` (118 of 4,000 labels, |Δθ| 6.5e-4); the other 11 are the same to
the bit.

Writes results/submodels_exact.md (``--suffix``: results/submodels_exact<suffix>.md). Usage::

    python -m benchmarks.submodels_exact [--against ba13a41] [--fits paper-20dB:5000,robot]
                                         [--suffix _65326d7]
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks._common import RESULTS, in_fresh_process, previous_tree
from benchmarks._fits import default_fit

ROOT = Path(__file__).resolve().parents[1]
FITS = ("paper-20dB:5000,paper-20dB:5001,paper-20dB:5002,paper-20dB:100,paper-25dB:5000,"
        "paper-25dB:100,paper-30dB:5001,paper-held:5000,rare-mode:5000,modes-5:5000,"
        "siso:5000,robot")


#: The sweep-stopping parameters of :class:`~pwa_pipeline.pwa.steps.submodels.RefinedSubModels` and
#: their values that turn them off.
RULES_OFF = {"split_sweep_tol": 0.0, "settle_tol": 0.0}


def worker(fit: str, rules: str, out: str) -> None:
    """One default fit (``case:seed`` or ``robot``), with the sweep-stopping rules ``off`` or
    as the default has them (``default``); θ_i, labels and regions to ``out``."""
    from sklearn.base import clone

    from pwa_pipeline.pwa.steps.submodels import RefinedSubModels

    est, u, y = default_fit(fit)
    subs = est.submodels if est.submodels is not None else RefinedSubModels()
    off = {k: v for k, v in RULES_OFF.items() if k in subs.get_params()}
    if rules == "off" and off:
        est.set_params(submodels=clone(subs).set_params(**off))
    model = est.fit(u, y)
    live = np.isfinite(model.regions_.intercept_)
    Path(out).write_text(json.dumps({
        "thetas": model.thetas_.tolist(), "labels": model.steps_["submodels"].labels_.tolist(),
        "coef": model.regions_.coef_.tolist(),
        "intercept": np.where(live, model.regions_.intercept_, 0.0).tolist()}))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default="ba13a41", help="the reference commit")
    parser.add_argument("--fits", default=FITS, help="comma-separated case:seed or robot")
    parser.add_argument("--suffix", default="", help="written to submodels_exact<suffix>.md")
    parser.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(*args.worker)
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        tree = previous_tree(args.against, tmp / args.against)
        if tree is None:
            sys.exit(f"cannot unpack {args.against}")
        for fit in args.fits.split(","):
            off, default, ref = (in_fresh_process("benchmarks.submodels_exact", [fit, r], tmp, t)
                                 for r, t in (("off", ROOT), ("default", ROOT), ("off", tree)))
            b = {k: np.asarray(v) for k, v in ref.items()}
            row = {"fit": fit, f"n_submodels {args.against}": len(b["thetas"])}
            for name, this in (("", off), (" (default)", default)):
                a = {k: np.asarray(v) for k, v in this.items()}
                same_shape = a["thetas"].shape == b["thetas"].shape
                row |= {
                    "n_submodels" + name: len(a["thetas"]),
                    "max |Δθ|" + name: float(np.abs(a["thetas"] - b["thetas"]).max())
                    if same_shape else np.inf,
                    "labels differing" + name: int((a["labels"] != b["labels"]).sum()),
                    "max |Δ region|" + name: float(max(
                        np.abs(a["coef"] - b["coef"]).max(),
                        np.abs(a["intercept"] - b["intercept"]).max())) if same_shape
                    else np.inf}
            rows.append(row)
            print(rows[-1])
    df = pd.DataFrame(rows)
    exact = bool(((df["max |Δθ|"] <= 1e-9) & (df["labels differing"] == 0)).all())
    rules = ", ".join(f"`{k}={v:g}`" for k, v in RULES_OFF.items())
    text = (f"This checkout with the sweep-stopping rules off ({rules}) "
            f"against `{args.against}`, each fit in a fresh process: "
            f"{'every fit the same' if exact else 'FITS DIFFER'}. The columns marked "
            f"(default): this checkout's default against it.\n\n"
            + df.to_markdown(index=False, floatfmt=".3g") + "\n")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"submodels_exact{args.suffix}.md").write_text(text)
    print(text)
    if not exact:
        sys.exit(1)


if __name__ == "__main__":
    main()
