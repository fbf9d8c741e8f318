"""MkDocs hooks: the configuration reference, generated at build time.

``docs/configuration.md`` holds two markers that this hook replaces:

- ``<!-- generated: estimators -->``: one table per estimator class, built from the class
  itself: its parameters and defaults from ``get_params()`` of an instance made with no
  arguments, the values of ``PWARX.paper()`` beside them, and each parameter's description
  from the numpydoc *Parameters* section of the class docstring (parsed by griffe, as the API
  reference is). Which step classes exist is found by walking the package for scikit-learn
  estimators, and which parameter of ``PWARX`` a class serves by the class names that the
  parameter's description mentions, so a class that moves to another module, or a parameter
  added or changed, shows up without editing this file.
- ``<!-- generated: hparams -->``: the sets of the bundled ``data/hparams.toml``.

Every page also drops the machine's load from the benchmark results it includes (`LOAD`):
a results file records the load its times were taken under, the docs show the figures.
"""

import importlib
import inspect
import pkgutil
import re
import tomllib
from pathlib import Path

ESTIMATORS_MARKER = "<!-- generated: estimators -->"
HPARAMS_MARKER = "<!-- generated: hparams -->"
PAGE = "configuration.md"
#: The load statements of the benchmarks' results (``benchmarks._common.describe_load`` and
#: older wordings), with the separator before them, and a paragraph left empty by them.
LOAD = re.compile(r"(?:[;,] )?1-minute load(?: average)? [\d.]+ at the start, [\d.]+ at the "
                  r"end(?:, [\d.]+% of the CPU time stolen by the hypervisor)?")
EMPTY_MACHINE = re.compile(r"<p>Machine: ?\.?</p>")

def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != PAGE:
        return markdown
    root = Path(config["config_file_path"]).resolve().parent
    if ESTIMATORS_MARKER in markdown:
        markdown = markdown.replace(ESTIMATORS_MARKER, estimators_reference())
    if HPARAMS_MARKER in markdown:
        markdown = markdown.replace(HPARAMS_MARKER, hparams_reference(root / "data" / "hparams.toml"))
    return markdown


def on_page_content(html: str, page, config, files) -> str:
    return EMPTY_MACHINE.sub("", LOAD.sub("", html))


# --- estimators -------------------------------------------------------------------------

def estimator_classes() -> dict[str, type]:
    """Every public scikit-learn estimator class defined in the numerical core."""
    from sklearn.base import BaseEstimator

    import pwa_pipeline

    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(pwa_pipeline.__path__, "pwa_pipeline."):
        if ".orchestration" in info.name or info.name.rsplit(".", 1)[-1].startswith("_"):
            continue  # the pipeline layer imports Dagster and MLflow and holds no estimator
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (inspect.isclass(obj) and issubclass(obj, BaseEstimator)
                    and obj.__module__ == module.__name__ and not name.startswith("_")
                    and not inspect.isabstract(obj)):
                found[name] = obj
    return found


def parameter_docs(cls: type) -> dict[str, str]:
    """``{parameter: description}`` from the numpydoc Parameters section of ``cls``."""
    import griffe

    docs: dict[str, str] = {}
    text = inspect.getdoc(cls) or ""
    sections = griffe.Docstring(text).parse("numpy", warnings=False)
    for section in sections:
        if section.kind.value == "parameters":
            for param in section.value:
                docs.setdefault(param.name, param.description)
    return docs


def _plain(text: str) -> str:
    """One table cell of Markdown from a docstring's description."""
    text = text.replace("``", "`")
    text = " ".join(text.split())
    return text.replace("|", "\\|")


def _value(value) -> str:
    if isinstance(value, str) and value.startswith("<required"):
        return "per data set"
    if hasattr(value, "get_params"):
        return f"`{type(value).__name__}()`"
    return f"`{value!r}`"


def _table(cls: type, key_prefix: str | None, paper: dict | None) -> str:
    params = cls().get_params(deep=False)
    if not params:
        return "No parameters."
    docs = parameter_docs(cls)
    order = [p for p in docs if p in params] + sorted(p for p in params if p not in docs)
    head = "| parameter | `hparams.toml` key | default |"
    rule = "|---|---|---|"
    if paper is not None:
        head += " `PWARX.paper` |"
        rule += "---|"
    head += " what it does |"
    rule += "---|"
    rows = [head, rule]
    for name in order:
        key = f"`{key_prefix}{name}`" if key_prefix is not None else "—"
        row = f"| `{name}` | {key} | {_value(params[name])} |"
        if paper is not None:
            row += f" {_value(paper[name]) if name in paper else '—'} |"
        rows.append(row + f" {_plain(docs.get(name) or '—')} |")
    return "\n".join(rows)


def _heading(cls: type) -> str:
    return f"### `{cls.__name__}`\n\n`{cls.__module__}.{cls.__name__}`"


def estimators_reference() -> str:
    from pwa_pipeline import PWARX
    from pwa_pipeline.baselines import __all__ as baseline_names

    classes = estimator_classes()
    required = "<required: per data set>"
    default = PWARX.default().get_params(deep=True)
    paper = PWARX.paper(na=1, nb=1, n_rho=required, eps=required, min_pts=required).get_params(deep=True)
    pwarx_docs = parameter_docs(PWARX)
    out = ["## `PWARX`", "",
           "Keys at the top of a set's table in `hparams.toml`; `preset = \"default\"`, "
           "`\"paper\"` or `\"auto\"` chooses the step objects (`PWARX.default`, "
           "`PWARX.paper`, `PWARX.auto`: the structure search, `na` and `nb` its largest "
           "orders).", "",
           _table(PWARX, "", None), ""]

    listed = {"PWARX"}
    for param, description in pwarx_docs.items():
        if param not in PWARX().get_params(deep=False):
            continue
        serving = [c for n, c in classes.items() if n != "PWARX" and re.search(rf"\b{n}\b", description)]
        if not serving:
            continue
        out += [f"## Step `{param}`", "", _plain(description), ""]
        for cls in serving:
            listed.add(cls.__name__)
            step_paper = None
            if type(paper.get(param)) is cls:
                step_paper = {k.split("__", 1)[1]: v for k, v in paper.items() if k.startswith(f"{param}__")}
            role = []
            if type(default.get(param)) is cls:
                role.append("the default's step")
            if type(paper.get(param)) is cls:
                role.append("the paper's step")
            out += [_heading(cls) + (f" ({', '.join(role)})" if role else ""), "",
                    _table(cls, f"{param}.", step_paper), ""]

    out += ["## Baselines", "",
            "`LinearARX` takes `na`, `nb`, `affine`, `form`, `outputs` and `refinement` from the "
            "same set as the PWA model, so the comparison is like for like; `SubspaceSS` is "
            "configured in `[baselines.<dataset>]` under `subspace.`.", ""]
    for name in baseline_names:
        cls = classes.get(name)
        if cls is None:
            continue
        listed.add(name)
        prefix = "subspace." if name == "SubspaceSS" else ""
        out += [_heading(cls), "", _table(cls, prefix, None), ""]

    others = [c for n, c in sorted(classes.items()) if n not in listed and c().get_params()]
    if others:
        out += ["## Other estimators", ""]
        for cls in others:
            out += [_heading(cls), "", _table(cls, None, None), ""]
    return "\n".join(out)


# --- hyper-parameter sets ------------------------------------------------------------------

def _flatten(table: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in table.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def hparams_reference(path: Path) -> str:
    with open(path, "rb") as f:
        sets = tomllib.load(f)
    out = []
    for name, per_dataset in sets.items():
        title = "Baselines (`[baselines.<dataset>]`)" if name == "baselines" else f"Set `{name}`"
        out += [f"### {title}", "", "| data set | keys |", "|---|---|"]
        for dataset, table in per_dataset.items():
            keys = ", ".join(f"`{k} = {_toml(v)}`" for k, v in _flatten(table).items())
            label = "every registered data set (`\"*\"`)" if dataset == "*" else f"`{dataset}`"
            out.append(f"| {label} | {keys} |")
        out.append("")
    return "\n".join(out)
