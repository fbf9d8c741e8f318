"""The README's screenshots of both UIs, and how long a first UI session takes.

    python -m benchmarks.screenshots            # writes docs/screenshots/*.png and
                                                # benchmarks/results/ui_first_run.{json,md}

On fresh stores in a temporary directory it does what the README tells a new user to do:
start ``dagster dev`` and ``mlflow ui`` (:class:`benchmarks._ui.UIStack`), launch
``hure_vasak|paper`` from *Jobs → sweep* in chromium and wait for the run, then photograph
the asset graph (grouped, top to bottom), an asset page's figure (on a 1366×768 laptop
screen), MLflow's chart view of the headline metrics, a run's page with its description, the
compare view, the model registry and a registered model version with its tags (MLflow's
first-visit pop-ups closed); last it runs the same partition from the command line and
photographs the sweep job's runs (256-colour PNGs, 1280×800 unless said). It times the start
of each server (to the code location loaded / ``/health`` answering), the run from the click
on *Launch 1 run* to its end, and splits the run into its wait in the run queue, the run
worker's start and the steps' own compute. ``--store DIR`` keeps the stores in DIR (which
must not exist yet); ``--out DIR`` writes the screenshots elsewhere. The servers are ended on
the way out, also on an error.
"""

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._ui import (
    LAPTOP,
    LOCATION,
    ROOT,
    VIEWPORT,
    chromium,
    compare_all_runs,
    dismiss_mlflow_popups,
    launch_from_sweep,
    mlflow_experiment_id,
    mlflow_popups,
    mlflow_runs_url,
    open_asset_graph,
    open_figure,
    search_charts,
    ui_stack,
    wait_for_run,
)

SHOTS = ROOT / "docs" / "screenshots"
RESULTS = ROOT / "benchmarks" / "results"
DATASET, HPARAMS = "hure_vasak", "paper"
#: Taller pages for the asset graph and the chart view: all of either in one picture.
TALL = {"width": 1280, "height": 1000}


def save(page, path: Path) -> None:
    """A screenshot of the viewport, reduced to 256 colours (UI pages lose nothing visible);
    never one with an MLflow pop-up over it (MLflow's pages are those routed after ``#``)."""
    from PIL import Image

    page.wait_for_timeout(800)  # let charts and fonts settle
    if "/#/" in page.url and mlflow_popups(page):
        raise RuntimeError(f"{path.name}: MLflow's {mlflow_popups(page)} over the page")
    page.screenshot(path=path)
    with Image.open(path) as image:
        small = image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    small.save(path, optimize=True)
    print(f"  {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}"
          f" ({path.stat().st_size // 1024} kB)")


def timings(run: dict, clicked: float) -> dict:
    steps = run["stepStats"]
    compute = sum(s["endTime"] - s["startTime"] for s in steps)
    first_step = min(s["startTime"] for s in steps)
    return {
        "launch_to_success_s": run["endTime"] - clicked,  # the server's clock is this one
        "queued_s": run["startTime"] - run["creationTime"],
        "run_s": run["endTime"] - run["startTime"],
        "worker_start_s": first_step - run["startTime"],
        "steps_compute_s": compute,
        "steps": len(steps),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--store", type=Path, help="keep the stores here (a new directory)")
    parser.add_argument("--out", type=Path, default=SHOTS, help=f"default {SHOTS}")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    store = args.store or Path(tempfile.mkdtemp(prefix="pwa-ui-")) / "store"
    if store.exists():
        parser.error(f"--store {store} exists: the measurement needs fresh stores")
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    with ui_stack(store) as stack, chromium() as browser:
        up = {name: server.up_seconds for name, server in stack.servers.items()}
        print(f"dagster dev up (code location loaded) after {up['dagster']:.1f} s, "
              f"mlflow ui after {up['mlflow']:.1f} s")
        page = browser.new_context(viewport=VIEWPORT).new_page()
        page.set_default_timeout(60_000)
        clicked = time.time()
        run_id = launch_from_sweep(page, stack, DATASET, HPARAMS)
        run = wait_for_run(page, stack, run_id)
        if run["status"] != "SUCCESS":
            print(f"run {run_id} ended {run['status']}", file=sys.stderr)
            return 1
        times = timings(run, clicked)
        print(f"{DATASET}|{HPARAMS} launched from Jobs → sweep: {times['launch_to_success_s']:.1f} s"
              f" to success, of which {times['steps_compute_s']:.1f} s in its steps")

        from pwa_pipeline.definitions import defs

        assets = len(defs.resolve_asset_graph().get_all_asset_keys())
        graph = browser.new_context(viewport=TALL).new_page()  # its layout choices stay here
        graph.goto(f"{stack.dagster_url}/asset-groups")
        graph.get_by_text("identification").first.wait_for()
        graph.get_by_text("Hide navigation").click()
        open_asset_graph(graph, stack, assets)
        graph.locator("[aria-label=panel_show_right]").last.click()  # hides the asset tree
        save(graph, args.out / "dagster-asset-graph.png")

        laptop = browser.new_context(viewport=LAPTOP).new_page()
        open_figure(laptop, stack, "pwa_scores", "prediction")
        save(laptop, args.out / "dagster-asset-figure.png")

        experiment = mlflow_experiment_id(stack, DATASET)
        paper = f"tags.hparams = '{HPARAMS}'"  # the set's runs, not the leaderboard's
        charts = browser.new_context(viewport=TALL).new_page()
        charts.goto(mlflow_runs_url(stack, experiment, paper, charts=True))
        charts.get_by_text("Model metrics").first.wait_for()
        dismiss_mlflow_popups(charts)
        search_charts(charts, "^(one_step|free_run)_(nrmse|r2)$|^fit_seconds$")  # headline
        charts.get_by_text("one_step_r2", exact=True).first.wait_for()
        save(charts, args.out / "mlflow-runs.png")

        # *Model training* at the top left, once for the browser (docs/pipeline.md): the
        # pages after it, linked without the view in their address, stay in that view
        page.goto(f"{stack.mlflow_url}/#/experiments")
        dismiss_mlflow_popups(page)
        page.get_by_text("Model training", exact=True).first.click()
        page.goto(mlflow_runs_url(stack, experiment, paper))
        page.get_by_role("link", name=f"pwa|{HPARAMS}", exact=True).click()
        page.get_by_text("Duration", exact=True).first.wait_for()
        dismiss_mlflow_popups(page)
        save(page, args.out / "mlflow-run.png")

        page.goto(mlflow_runs_url(stack, experiment, paper))
        page.get_by_role("link", name=f"pwa|{HPARAMS}", exact=True).wait_for()
        compare_all_runs(page)
        page.get_by_text("Comparing 3 Runs").wait_for()
        page.get_by_text("Visualizations", exact=True).click()  # folded: names above metrics
        page.get_by_text("Parameters", exact=True).last.click()
        dismiss_mlflow_popups(page, settle_ms=0)
        save(page, args.out / "mlflow-compare.png")

        page.goto(f"{stack.mlflow_url}/#/models")
        page.get_by_role("link", name=f"pwa-pipeline.{DATASET}.pwa", exact=True).wait_for()
        dismiss_mlflow_popups(page)  # the registry's announcement
        save(page, args.out / "mlflow-models.png")

        page.goto(f"{stack.mlflow_url}/#/models/pwa-pipeline.{DATASET}.pwa/versions/1")
        page.get_by_role("cell", name="dagster_run_id", exact=True).wait_for()
        dismiss_mlflow_popups(page, settle_ms=500)
        save(page, args.out / "mlflow-model-version.png")

        session = time.perf_counter() - t0
        t_cli = time.perf_counter()
        done = stack.cli("run", "--partition", f"{DATASET}|{HPARAMS}")
        if done.returncode:
            print(done.stdout[-3000:], file=sys.stderr)
            return 1
        print(f"`python -m pwa_pipeline run --partition {DATASET}|{HPARAMS}` on the same "
              f"stores: {time.perf_counter() - t_cli:.1f} s")
        page.goto(f"{stack.dagster_url}/locations/{LOCATION}/jobs/sweep/runs")
        page.get_by_text(run_id[:8], exact=True).first.wait_for()
        save(page, args.out / "dagster-sweep-runs.png")
    result = {
        "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "cpus": os.cpu_count(), "load_before": load_before, "load_after": os.getloadavg(),
        "dagster_up_s": up["dagster"], "mlflow_up_s": up["mlflow"],
        "partition": f"{DATASET}|{HPARAMS}", **times,
        "session_s": session,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ui_first_run.json").write_text(json.dumps(result, indent=2) + "\n")
    (RESULTS / "ui_first_run.md").write_text(markdown(result))
    print(markdown(result), end="")
    return 0


def markdown(r: dict) -> str:
    load = lambda t: " / ".join(f"{x:.2f}" for x in t)  # noqa: E731
    key = r["partition"].replace("|", "\\|")  # a pipe inside a table cell
    return f"""# A first UI session on fresh stores

`python -m benchmarks.screenshots`, {r['when']}, {r['cpus']} CPUs, load average (1/5/15 min)
{load(r['load_before'])} before and {load(r['load_after'])} after (the run itself keeps both CPUs busy).

| | seconds |
|---|---|
| `dagster dev` started → code location loaded | {r['dagster_up_s']:.1f} |
| `mlflow ui` started → `/health` answers (at the same time) | {r['mlflow_up_s']:.1f} |
| `{key}`: *Launch 1 run* clicked → run succeeded | {r['launch_to_success_s']:.1f} |
| … queued → running (dequeue, the run worker's start and code load) | {r['queued_s']:.1f} |
| … running → first step | {r['worker_start_s']:.1f} |
| … its {r['steps']} steps' own compute (3 MLflow runs and models included) | {r['steps_compute_s']:.1f} |
| … the run, start to end | {r['run_s']:.1f} |
| the whole session (servers, run, screenshots; not the command-line run) | {r['session_s']:.1f} |
"""


if __name__ == "__main__":
    raise SystemExit(main())
