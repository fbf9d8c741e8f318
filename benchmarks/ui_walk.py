"""A walk through both UIs as a user takes it after two runs of the command line, with the
pages that say what a model is photographed for docs/pipeline.md.

    python -m benchmarks.ui_walk                 # writes docs/screenshots/walk-*.png

On fresh stores in a temporary directory (`benchmarks._ui.UIStack`: ``dagster dev`` and
``mlflow ui``) it runs ``python -m pwa_pipeline run`` on ``hure_vasak|auto`` and
``hure_vasak|default`` twice (the second run reuses both fitted models, and says so), then
photographs in chromium: the ``pwa_model`` page of ``hure_vasak|auto`` (what the model
is, whether it was fitted or reused, its ground truth), its structure search's table and
its switching figure, the leaderboard, an asset check's result (its partition named), and
in MLflow the runs of the ``auto`` set (one colour per method) and the registered PWA model
(its description, and its versions with their aliases: one per set, and ``best``). Each
page's text is written beside its PNG (``.txt``) in ``--text DIR`` when given, to read for
contradictions; the command line's two outputs too. ``--out DIR`` writes the screenshots
elsewhere. The servers are ended on the way out, also on an error.
"""

import argparse
import sys
import tempfile
from pathlib import Path

from benchmarks._ui import (
    chromium,
    dismiss_mlflow_popups,
    mlflow_experiment_id,
    mlflow_runs_url,
    ui_stack,
)
from benchmarks.screenshots import SHOTS, save

PARTITIONS = ("hure_vasak|auto", "hure_vasak|default")
MODEL = "pwa-pipeline.hure_vasak.pwa"


def show_markdown(page, key: str) -> None:
    """On an asset page: open the Markdown metadata ``key`` (*Show Markdown*)."""
    row = page.locator("tr", has=page.get_by_text(key, exact=True))
    row.get_by_text("[Show Markdown]").first.click()
    page.get_by_role("dialog").first.wait_for()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=SHOTS, help=f"default {SHOTS}")
    parser.add_argument("--text", type=Path, help="write each page's text and the command "
                                                  "line's output here")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.text:
        args.text.mkdir(parents=True, exist_ok=True)
    store = Path(tempfile.mkdtemp(prefix="pwa-walk-")) / "store"

    def shot(page, name: str) -> None:
        if args.text:
            (args.text / f"{name}.txt").write_text(page.inner_text("body"))
        save(page, args.out / f"{name}.png")

    with ui_stack(store) as stack, chromium() as browser:
        for i in (1, 2):
            done = stack.cli("run", *(a for p in PARTITIONS for a in ("--partition", p)),
                             timeout=1200)
            if args.text:
                (args.text / f"cli-{i}.txt").write_text(done.stdout)
            if done.returncode:
                print(done.stdout[-3000:], file=sys.stderr)
                return 1
        print(next(line for line in done.stdout.splitlines() if "reused" in line).strip())

        tall = browser.new_context(viewport={"width": 1280, "height": 1200}).new_page()
        tall.set_default_timeout(60_000)
        model_page = f"{stack.dagster_url}/assets/pwa_model?view=partitions&partition=" \
                     f"{PARTITIONS[0].replace('|', '%7C')}"
        tall.goto(model_page)
        tall.get_by_text("resolved parameters", exact=True).wait_for()
        shot(tall, "walk-dagster-model")
        page = browser.new_context(viewport={"width": 1280, "height": 1000}).new_page()
        page.set_default_timeout(60_000)
        page.goto(model_page)
        show_markdown(page, "structure search")
        shot(page, "walk-dagster-structure-search")
        laptop = browser.new_context(viewport={"width": 1366, "height": 768}).new_page()
        laptop.set_default_timeout(60_000)
        laptop.goto(model_page)
        show_markdown(laptop, "switching (first held-out experiment)")
        image = laptop.get_by_role("dialog").locator("img").first
        laptop.wait_for_function("i => i.complete", arg=image.element_handle())
        shot(laptop, "walk-dagster-switching")

        page.goto(f"{stack.dagster_url}/assets/leaderboard")
        show_markdown(page, "leaderboard")
        shot(page, "walk-dagster-leaderboard")
        page.goto(f"{stack.dagster_url}/assets/sub_models?view=checks")
        page.get_by_text("Latest execution").first.wait_for()
        shot(page, "walk-dagster-check")

        page.goto(f"{stack.mlflow_url}/#/experiments")
        dismiss_mlflow_popups(page)
        page.get_by_text("Model training", exact=True).first.click()
        experiment = mlflow_experiment_id(stack, "hure_vasak")
        page.goto(mlflow_runs_url(stack, experiment,
                                  "tags.hparams = 'auto' and tags.latest = 'true'"))
        page.get_by_role("link", name="pwa|auto", exact=True).wait_for()
        dismiss_mlflow_popups(page, settle_ms=500)
        shot(page, "walk-mlflow-runs")
        page.set_viewport_size({"width": 1280, "height": 1200})  # its versions in view too
        page.goto(f"{stack.mlflow_url}/#/models/{MODEL}")
        page.get_by_text("Version 1", exact=True).first.wait_for()
        dismiss_mlflow_popups(page, settle_ms=500)
        shot(page, "walk-mlflow-registered-model")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
