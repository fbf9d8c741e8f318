"""The architecture of docs/architecture.md, checked against the code: the layers of
``pwa_pipeline`` (every import runs down, none across or up), no import cycle between modules,
the library importable and usable without the pipeline's libraries, and every name of the
architecture diagram an object of the code."""

import ast
import functools
import importlib
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "pwa_pipeline"
PAGE = ROOT / "docs" / "architecture.md"


def documented_layers() -> dict[str, int]:
    """Top-level module or package of ``pwa_pipeline`` → its layer, from the page's table
    (rows ``| n | `name`, `name` | … |``)."""
    layers = {}
    for number, names in re.findall(r"^\| (\d+) \| ([^|]+) \|", PAGE.read_text(), re.M):
        for name in re.findall(r"`([\w.]+)`", names):
            layers[name] = int(number)
    return layers


def modules() -> dict[str, Path]:
    """Dotted name → file of every module of the package (a package by its __init__.py)."""
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def imports(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports, at module level or inside functions
    (``from a import b`` counts as module ``a.b`` where that is a module)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in known else module
                       for a in node.names]
        else:
            continue
        found |= {t for t in targets if t in known and t != name}
    return found


def top(name: str) -> str:
    """``pwa_pipeline.pwa.steps.base`` → ``pwa``; the package itself → ``__init__``."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_import_runs_down_the_documented_layers():
    layers = documented_layers()
    known = modules()
    tops = {top(name) for name in known}
    assert tops == set(layers), f"layers of {PAGE.name} and the package differ"
    wrong = sorted(f"{a} ({layers[top(a)]}) imports {b} ({layers[top(b)]})"
                   for a, path in known.items() for b in imports(a, path, known)
                   if top(a) != top(b) and layers[top(b)] >= layers[top(a)])
    assert wrong == []


def test_no_module_imports_itself_through_others():
    known = modules()
    graph = {name: imports(name, path, known) for name, path in known.items()}
    # a package's face (__init__.py) hands on what its modules define: importing the face
    # from one of its own modules would be a cycle, so faces are kept in the graph
    state: dict[str, int] = {}
    cycles = []

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(trail[trail.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, trail + [nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
    assert cycles == []


def test_the_mutation_of_an_upward_import_is_caught(tmp_path):
    """The layer check itself: an import of the pipeline from the estimator is reported."""
    known = modules()
    path = tmp_path / "estimator.py"
    path.write_text(known["pwa_pipeline.pwa.estimator"].read_text()
                    + "\n\ndef f():\n    from ..orchestration import settings\n")
    assert "pwa_pipeline.orchestration.settings" in imports("pwa_pipeline.pwa.estimator",
                                                            path, known)
    assert documented_layers()["orchestration"] > documented_layers()["pwa"]


#: What the pipeline, the figures and the stability report bring; the library must work
#: without any of them (``pip install pwa-pipeline``).
NOT_IN_THE_LIBRARY = ("dagster", "mlflow", "dask", "matplotlib", "cvxpy", "playwright",
                      "mkdocs", "pyarrow", "tabulate")

LIBRARY_USE = f"""
import importlib, pkgutil, sys
blocked = {NOT_IN_THE_LIBRARY!r}

class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in blocked:
            raise ImportError(f"blocked: {{name}}")

sys.meta_path.insert(0, Block())
import pwa_pipeline
for info in pkgutil.walk_packages(pwa_pipeline.__path__, "pwa_pipeline."):
    if info.name.split(".")[1] not in ("orchestration", "definitions", "__main__"):
        importlib.import_module(info.name)
from pwa_pipeline import PWARX, SubspaceSS, make_hure_vasak
from pwa_pipeline.control import HybridMPC
data = make_hure_vasak(n_samples=600, snr_db=None, seed=3)
model = PWARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
ss = model.to_state_space()
mpc = HybridMPC(ss, horizon=2)
SubspaceSS(order=2).fit(data.u_train[0], data.y_train[0]).to_state_space(
    data.u_train[0], data.y_train[0])
from pwa_pipeline.plotting import SwitchingDisplay
try:
    SwitchingDisplay.from_estimator(model, data.u_train[0], data.y_train[0])
except ImportError as exc:
    print(exc)
print("modes", model.n_submodels_, sorted(m for m in sys.modules if m.split(".")[0] in blocked))
"""


def test_the_library_works_without_the_pipelines_libraries():
    """Every module outside the orchestration imports, and a fit, its state-space form and
    an MPC work, with the pipeline's and the figures' libraries made unimportable; a figure
    then says which extra to install."""
    done = subprocess.run([sys.executable, "-c", LIBRARY_USE], capture_output=True,
                          text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.strip().splitlines()
    assert lines[-1] == "modes 4 []"
    assert lines[0] == ('Drawing a figure needs matplotlib, which is not installed: '
                        'pip install "pwa-pipeline[plot]"')


def diagram():
    spec = importlib.util.spec_from_file_location(
        "architecture_figure", ROOT / "docs" / "scripts" / "architecture_figure.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.DIAGRAM


def code_words(label: str) -> list[str]:
    """The words of a label that look like code: ASCII with an underscore or a lower-case
    letter between capitals (``groups_``, ``*_scores``, ``OutputGroup``); not ``MLflow``,
    ``NRMSE`` or ``θ_k``."""
    words = [w.strip("*") for w in re.split(r"[\s,:|()→…]+", label)]
    return [w for w in words if w.isascii() and w and ("_" in w or re.search(r"[A-Z][a-z]+[A-Z]", w))]


@functools.cache
def names_in_the_code() -> frozenset[str]:
    """Every identifier of the package's source and every word of its strings."""
    names = set()
    for path in modules().values():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Name):
                names.add(node.id)
            elif isinstance(node, ast.Attribute):
                names.add(node.attr)
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                names |= set(re.findall(r"\w+", node.value))
    return frozenset(names)


@pytest.mark.parametrize("entry", [e for column in diagram() for e in column.entries],
                         ids=lambda e: e.label)
def test_every_name_of_the_diagram_is_an_object_of_the_code(entry):
    """The object an entry stands for exists, and so does every code-like word of its label
    (an attribute, method or asset renamed in the code fails here until the diagram follows)."""
    kind, _, name = entry.ref.partition(":")
    if kind == "asset":
        import dagster as dg

        from pwa_pipeline.definitions import defs

        assert dg.AssetKey(name) in defs.resolve_asset_graph().get_all_asset_keys()
    else:
        assert hasattr(importlib.import_module(kind), name), entry.ref
    missing = [w for w in code_words(entry.label) if w not in names_in_the_code()]
    assert missing == []


def test_a_stale_name_in_the_diagram_is_caught():
    assert code_words("groups_: OutputGroup, *_scores, MLflow, NRMSE, θ_k") == [
        "groups_", "OutputGroup", "_scores"]
    assert "groups_" in names_in_the_code() and "group_list_" not in names_in_the_code()
