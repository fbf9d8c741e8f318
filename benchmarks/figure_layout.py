"""The parameter-clusters figure (drawn by the ``clusters`` asset of every set) with its
hand layout against matplotlib's constrained layout, which it had before.

The robot's default and paper settings are fitted through step 4 once; then the figure of
each is built and rendered to PNG (:func:`~pwa_pipeline.orchestration.images.to_png`)
``--repeats`` times each way, the two ways alternating so that they share the machine's
load: as drawn (laid out by hand) and with the constrained layout engine set on the same
figure before rendering. Reported: the median seconds of the PNG rendering each way and
their ratio; how busy the machine was (``MachineLoad``).

Writes results/figure_layout.json and results/figure_layout.md.
Usage: python -m benchmarks.figure_layout [--repeats 10]
"""

import argparse
import statistics

import pandas as pd
from sklearn.base import clone

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from pwa_pipeline._validation import as_experiments
from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import load_kuka
from pwa_pipeline.orchestration.images import to_png
from pwa_pipeline.plotting import ParameterClustersDisplay
from pwa_pipeline.regressors import build_regressors


def rendering_seconds(setting: str, repeats: int) -> dict:
    """Median seconds of the figure's PNG with each layout, for one hyper-parameter set."""
    robot = load_kuka()
    pwa = HParamsFile().configuration(setting, "kuka_robot").pwa
    reg = build_regressors(as_experiments(robot.u_train, robot.y_train), pwa.na, pwa.nb,
                           pwa.affine)
    steps = pwa.step_objects()
    local = clone(steps["local_models"]).fit(reg.phi, reg.target)
    clustering = clone(steps["clustering"]).fit(local, reg.target)
    seconds = {"hand": [], "constrained": []}
    for _ in range(repeats):
        for layout in seconds:
            fig = ParameterClustersDisplay.from_steps(local, clustering, reg.target).figure_
            if layout == "constrained":
                fig.set_layout_engine("constrained")
            with Timer() as t:
                to_png(fig)
            seconds[layout].append(t.seconds)
    hand, constrained = (statistics.median(seconds[k]) for k in ("hand", "constrained"))
    return {"setting": setting, "clusters": clustering.n_clusters_, "hand_seconds": hand,
            "constrained_seconds": constrained, "constrained_over_hand": constrained / hand}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args(argv)
    load = MachineLoad()
    rows = [rendering_seconds(setting, args.repeats) for setting in ("default", "paper")]
    machine = load.summary()
    write_json({"rows": rows, "repeats": args.repeats, "machine_load": machine},
               "figure_layout")
    text = (f"The robot's parameter-clusters figure rendered to PNG, {args.repeats} times each "
            f"way, alternated; medians in seconds; {describe_load(machine)}.\n\n"
            + pd.DataFrame(rows).to_markdown(index=False, floatfmt=".3g") + "\n")
    (RESULTS / "figure_layout.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
