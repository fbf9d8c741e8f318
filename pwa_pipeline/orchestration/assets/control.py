"""The PWA model in the form controller design takes: a PWA state-space model on polyhedral
regions (``pwa_pipeline.control``), its stability verdict, and its files."""

import time
from dataclasses import dataclass

import dagster as dg
import numpy as np

from ...config import Configuration
from ...control import PWAStateSpace, StabilityReport
from ...datasets import Dataset
from ...methods import METHODS
from ...plotting import PartitionDisplay, context_title
from ...pwa import PWARX
from ..checks import described, per_partition
from ..files import atomic_write, inside
from ..images import to_markdown
from ..reporting import rounded
from ..settings import PipelineSettings

#: The files of each partition's state-space model, in ``<exports>/<dataset>/<set>/``.
JSON_FILE, MPT3_FILE = "pwa_state_space.json", "pwa_system.m"
CONTROL_CHECKS = [dg.AssetCheckSpec(
    "exported", asset="control_model",
    description="The PWA model converts to a state-space model with at least one region "
                "inside the data envelope (warning: the scores run without it).")]


@dataclass(frozen=True)
class ControlModel:
    """A partition's PWA state-space model, its stability report, and its files (name →
    text: the JSON and the MPT3 script), written once and logged by the PWA scores."""

    state_space: PWAStateSpace
    stability: StabilityReport
    files: dict[str, str]


def control_model_asset(partitions_def):
    @dg.asset(partitions_def=partitions_def, group_name="models", kinds={"scipy"},
              check_specs=CONTROL_CHECKS, description=(
                  "The PWA model as a PWA state-space model x⁺ = A_i x + B_i u + f_i, "
                  "y = C_i x + g_i on polyhedral regions H_i [x; u] ≤ h_i inside the "
                  "envelope of the training data (`pwa_pipeline.control`), for controller "
                  "design: its region count, envelope and stability verdict, its JSON and "
                  "MPT3 script as files (paths below; also artifacts of the PWA model's "
                  "MLflow run), and its regions drawn in a 2-D slice. A model that does not "
                  "convert is said so here and by the check `exported`; the scores run "
                  "all the same."))
    def control_model(context: dg.AssetExecutionContext, settings: PipelineSettings,
                      configuration: Configuration, raw_benchmark: Dataset, pwa_model: PWARX):
        data, t0 = raw_benchmark, time.perf_counter()
        try:
            ss = pwa_model.to_state_space(data.u_train, data.y_train,
                                          input_names=data.u_names, output_names=data.y_names)
        except (NotImplementedError, ValueError) as exc:
            context.log.warning(f"control_model: not exported: {exc}")
            yield dg.Output(None, metadata={"exported": False, "reason": str(exc)})
            yield dg.AssetCheckResult(check_name="exported", passed=False,
                                      severity=dg.AssetCheckSeverity.WARN,
                                      description=described(str(context.partition_key),
                                                            False, f"not exported: {exc}"),
                                      metadata={"partition": str(context.partition_key),
                                                "reason": str(exc)})
            return
        convert_seconds = time.perf_counter() - t0
        report = ss.stability()
        folder = inside(settings.exports_root(), configuration.dataset, configuration.hparams)
        files = {JSON_FILE: ss.to_json(), MPT3_FILE: ss.to_mpt3(Ts=data.sample_time)}
        for name, text in files.items():
            atomic_write(folder / name, lambda path, text=text: path.write_text(text))
        states = ss.states(data.u_train, data.y_train)
        inputs = [u[ss.n_initial:] for u in data.u_train]
        fixed = np.median(np.hstack([np.vstack(states), np.vstack(inputs)]), axis=0)
        names = [data.label(name) for name in [*ss.state_names, *ss.input_names]]
        figure = PartitionDisplay.from_state_space(
            ss, fixed, context_title(configuration.dataset, configuration.hparams,
                                     METHODS["pwa"].label), names).figure_
        held = int(np.sum(ss.held.any(axis=1)))
        modes = f"{ss.n_modes} region(s)" + (
            f" ({held} with an output held at its limit)" if held else "")
        context.log.info(f"control_model: {modes} in {ss.n_states} states; {report.message}")
        yield dg.Output(ControlModel(ss, report, files), metadata=rounded({
            "exported": True, "n_modes": ss.n_modes, "held_modes": held,
            "n_states": ss.n_states,
            "dropped_modes": len(ss.dropped_modes), "envelope padding": ss.padding,
            "stability": report.message, "lyapunov_certified": report.certified,
            "max_spectral_radius": float(np.max(report.spectral_radius)),
            "convert_seconds": convert_seconds,
            "stability_seconds": time.perf_counter() - t0 - convert_seconds,
            "json": dg.MetadataValue.path(str(folder / JSON_FILE)),
            "mpt3_script": dg.MetadataValue.path(str(folder / MPT3_FILE)),
            "regions": dg.MetadataValue.md(to_markdown(figure))}))
        yield dg.AssetCheckResult(check_name="exported", passed=True,
                                  description=described(str(context.partition_key), True,
                                                        f"{modes} exported"),
                                  metadata=per_partition(str(context.partition_key),
                                                         {"n_modes": ss.n_modes}))

    return control_model
