"""Export of the robot's PWA models to state space, and their stability report.

The KUKA robot's PWARX model of each set (``default``, ``paper``, ``robot``) is fitted once on
the training record (``PipelineSettings().dataset("kuka_robot")``, the set's configuration;
the fit is not what is timed, its time is recorded for reference). Then, as the pipeline's
``control_model`` asset does, ``model.to_state_space(u_train, y_train, …)`` (explicit regions
inside the data envelope) and ``ss.stability()`` (spectral radii, a common and else a
piecewise-quadratic Lyapunov function, with its default size and time bounds) are each run
``--repeats`` times. Records the median and every run's wall-clock seconds, the modes, states
and inputs, the regions dropped as empty, the verdict (certified, method, message) and the
number of mode transitions when the piecewise search computed them. The targets are an
export within 5 s and a stability report within 30 s.

Writes results/control_export.md and results/control_export.json. Usage:
python -m benchmarks.control_export [--repeats 3] [--sets default paper robot]
"""

import argparse
import statistics
import time

from sklearn.base import clone

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from pwa_pipeline.orchestration.settings import PipelineSettings

SETS = ("default", "paper", "robot")
EXPORT_TARGET, STABILITY_TARGET = 5.0, 30.0


def measure(settings: PipelineSettings, data, name: str, repeats: int) -> dict:
    """Fit the set's model once, then time the export and the stability report."""
    t0 = time.perf_counter()
    model = clone(settings.configuration(name, "kuka_robot").pwa).fit(data.u_train,
                                                                      data.y_train)
    fit_seconds = time.perf_counter() - t0
    export, stability = [], []
    for _ in range(repeats):
        with Timer() as t:
            ss = model.to_state_space(data.u_train, data.y_train, input_names=data.u_names,
                                      output_names=data.y_names)
        export.append(t.seconds)
    for _ in range(repeats):
        with Timer() as t:
            report = ss.stability()
        stability.append(t.seconds)
    return {
        "set": name, "structures": "; ".join(dict.fromkeys(ss.source["structures"])),
        "fit_seconds": fit_seconds,
        "modes": ss.n_modes, "states": ss.n_states, "inputs": ss.n_inputs,
        "outputs": ss.n_outputs, "dropped_modes": len(ss.dropped_modes),
        "export_seconds": statistics.median(export), "export_runs": export,
        "stability_seconds": statistics.median(stability), "stability_runs": stability,
        "certified": report.certified, "method": report.method, "message": report.message,
        "max_spectral_radius": float(report.spectral_radius.max()),
        "modes_with_radius_at_least_1": int((report.spectral_radius >= 1).sum()),
        "transitions": None if report.transitions is None else len(report.transitions),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--sets", nargs="+", default=list(SETS))
    args = parser.parse_args(argv)
    load = MachineLoad()
    settings = PipelineSettings()
    data = settings.dataset("kuka_robot")
    rows = []
    for name in args.sets:
        rows.append(measure(settings, data, name, args.repeats))
        print(f"{name}: {rows[-1]['modes']} modes, export {rows[-1]['export_seconds']:.3f} s, "
              f"stability {rows[-1]['stability_seconds']:.3f} s", flush=True)
    result = {"repeats": args.repeats, "export_target_seconds": EXPORT_TARGET,
              "stability_target_seconds": STABILITY_TARGET, "sets": rows,
              "machine_load": load.summary()}
    write_json(result, "control_export")
    lines = [
        f"The KUKA robot's PWARX model of each set exported with `to_state_space` and its "
        f"stability report `stability()`: wall-clock medians of {args.repeats} runs (the fit "
        f"is not timed). Targets: export ≤ {EXPORT_TARGET:g} s, stability ≤ "
        f"{STABILITY_TARGET:g} s.", "",
        "| set | structures | modes | states | inputs | export s | stability s | modes ρ ≥ 1 "
        "(largest ρ) | certified | method |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['set']} | {r['structures']} | {r['modes']} | {r['states']} | {r['inputs']} | "
            f"{r['export_seconds']:.3f} | {r['stability_seconds']:.3f} | "
            f"{r['modes_with_radius_at_least_1']} ({r['max_spectral_radius']:.4f}) | "
            f"{'yes' if r['certified'] else 'no'} | {r['method']} |")
    lines += ["", "Verdicts:", ""]
    lines += [f"- {r['set']}: {r['message']}" for r in rows]
    lines += ["", "Fits (not timed above): "
              + ", ".join(f"{r['set']} {r['fit_seconds']:.1f} s" for r in rows) + ".", "",
              f"Machine: {describe_load(result['machine_load'])}."]
    (RESULTS / "control_export.md").write_text("\n".join(lines) + "\n")
    print((RESULTS / "control_export.md").read_text())


if __name__ == "__main__":
    main()
