"""The PWA state-space model as a versioned JSON document (`SCHEMA`, version
`SCHEMA_VERSION`): what [`PWAStateSpace.to_json`][pwa_pipeline.control.PWAStateSpace.to_json] writes and
``from_json`` reads.

The document is an object with

- ``schema`` (``"pwa-pipeline/pwa-state-space"``) and ``schema_version`` (2);
- ``n_modes`` s, ``n_states`` n, ``n_inputs`` r, ``n_outputs`` m, ``output_lags`` L,
  ``input_lags`` nb (null for a state that is not made of past values), ``affine``;
- ``state_names`` (n), ``input_names`` (r), ``output_names`` (m);
- ``A`` (s × n × n), ``B`` (s × n × r), ``f`` (s × n), ``C`` (s × m × n), ``D``
  (s × m × r), ``g`` (s × m), nested lists in row-major order;
- ``regions``: s objects ``{"H": k_i × (n + r), "h": k_i}``, P_i = {z : H z ≤ h}
  over z = [x; u];
- ``envelope``: ``{"lower": n + r, "upper": n + r, "padding": share}``;
- ``mode_regions`` (s × m) and ``dropped_modes`` (k × m): each mode's, and each
  dropped combination's, region of every output's sub-model in the fitted model;
- ``source``: what the model was converted from (for the record).

Version 1 documents (no ``D``, a state of past values) are read as well.

Numbers are written with 17 significant digits, so a round trip is exact.
"""

import json
from collections.abc import Callable
from itertools import combinations
from pathlib import Path

import numpy as np

from .polyhedra import EMPTY_RADIUS, Box, chebyshev_ball

#: Identifies the JSON document.
SCHEMA = "pwa-pipeline/pwa-state-space"

#: The version of the document this code writes (it reads this and the earlier ones).
SCHEMA_VERSION = 2
#: The versions it reads.
READ_VERSIONS = (1, 2)

#: The fields of a document (version 1 has all but ``D``).
FIELDS = ("schema", "schema_version", "n_modes", "n_states", "n_inputs", "n_outputs",
          "output_lags", "input_lags", "affine", "state_names", "input_names", "output_names",
          "A", "B", "f", "C", "D", "g", "regions", "envelope", "mode_regions",
          "dropped_modes", "source")

#: Each numeric field and its number of list levels.
_ARRAYS = {"A": 3, "B": 3, "f": 2, "C": 3, "D": 3, "g": 2}


def to_document(ss) -> dict:
    """The JSON document of a [`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace] as Python objects."""
    lower, upper = ss.envelope
    return {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "n_modes": ss.n_modes, "n_states": ss.n_states, "n_inputs": ss.n_inputs,
        "n_outputs": ss.n_outputs,
        "output_lags": ss.output_lags, "input_lags": ss.input_lags,
        "affine": ss.affine,
        "state_names": ss.state_names, "input_names": ss.input_names,
        "output_names": ss.output_names,
        "A": ss.A.tolist(), "B": ss.B.tolist(), "f": ss.f.tolist(),
        "C": ss.C.tolist(), "D": ss.D.tolist(), "g": ss.g.tolist(),
        "regions": [{"H": H.tolist(), "h": h.tolist()} for H, h in ss.regions],
        "envelope": {"lower": lower.tolist(), "upper": upper.tolist(),
                     "padding": ss.padding},
        "mode_regions": ss.mode_regions.tolist(),
        "dropped_modes": ss.dropped_modes.tolist(),
        "source": ss.source,
    }


def write_json(ss, path: str | Path | None = None) -> str:
    """The model as a JSON document (see the module doc), also written to ``path`` when
    given."""
    text = json.dumps(to_document(ss), indent=1)
    if path is not None:
        Path(path).write_text(text)
    return text


def read_json(source: str | Path, model: Callable):
    """A model read from a JSON document written by `write_json`, built by
    ``model`` (the state-space class, called with the document's matrices, regions and
    options).

    Every field is required (``D`` from version 2 on) and of its own JSON type: nothing is
    converted (``"false"`` is not a boolean, 1.7 not a whole number) and nothing takes a
    default. The regions must each hold a ball inside the envelope, no two may overlap
    there (a region without rows, all of z, only in a model of one mode), and together they
    must cover it (a sampled check, `_uncovered`), as `to_state_space` makes them: a
    partition of the envelope.

    Parameters
    ----------
    source : str or Path
        The JSON text, or the path of a file holding it. A str that is not JSON text is a
        path; pass a ``Path`` for a file whose name is itself JSON (``3``, ``null``).
    model : callable
    [`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace].

    Raises
    ------
    ValueError
        If the document is not JSON, not an object, nested too deeply, of another schema
        or schema version, lacks a field, a field is not of its type or does not have the
        shape the others imply, or the regions are empty, overlap or leave a point of the
        envelope uncovered (the message names the field, or the point).
    """
    doc = _document(source)
    if doc.get("schema") != SCHEMA:
        raise ValueError(f"not a PWA state-space document: schema is "
                         f"{_show(doc.get('schema'))}, expected {SCHEMA!r}")
    version = doc.get("schema_version")
    if isinstance(version, bool) or version not in READ_VERSIONS:
        raise ValueError(f"schema version {version!r} is not supported: "
                         f"this version of pwa-pipeline reads versions {list(READ_VERSIONS)}")
    missing = [k for k in FIELDS if k not in doc and not (k == "D" and version == 1)]
    if missing:
        raise ValueError(f"the document lacks field(s) {missing}")
    _check_fields(doc)
    envelope, regions = doc["envelope"], doc["regions"]
    ss = model(doc["A"], doc["B"], doc["f"], doc["C"], doc["g"],
               [(r["H"], r["h"]) for r in regions], envelope["lower"], envelope["upper"],
               output_lags=doc["output_lags"], input_lags=doc["input_lags"],
               affine=doc["affine"], D=doc.get("D"),
               input_names=doc["input_names"], output_names=doc["output_names"],
               state_names=None if doc["output_lags"] is not None else doc["state_names"],
               padding=envelope["padding"], mode_regions=doc["mode_regions"],
               dropped_modes=doc["dropped_modes"], source=doc["source"])
    for key, expected in (("n_modes", ss.n_modes), ("n_states", ss.n_states),
                          ("n_inputs", ss.n_inputs), ("n_outputs", ss.n_outputs)):
        if doc[key] != expected:
            raise ValueError(f"{key} is {doc[key]!r} but the matrices give {expected}")
    if doc["state_names"] != ss.state_names:
        raise ValueError(f"state_names {doc['state_names']} do not match the orders and "
                         f"names, which give {ss.state_names}")
    _check_regions(ss)
    return ss


def _document(source: str | Path) -> dict:
    """The parsed document of ``source`` (see `read_json`), an object."""
    if isinstance(source, Path):
        doc = _loads(source.read_text())
    else:
        text = str(source)
        if text.lstrip().startswith(("{", "[")):
            doc = _loads(text)
        else:
            try:  # a JSON value that cannot be a document (null, 3, "…"), refused below
                doc = _loads(text)
            except ValueError:
                doc = _loads(Path(text).read_text())
    if not isinstance(doc, dict):
        raise ValueError(f"the JSON document is {_kind(doc)}, not an object")
    return doc


def _loads(text: str):
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("not a JSON document: nested too deeply (a PWA state-space "
                         "document has at most five levels)") from None
    except ValueError as exc:  # JSONDecodeError, or an integer of too many digits
        raise ValueError(f"not a JSON document: {exc}") from None


def _kind(value) -> str:
    """The JSON type of a parsed value, in words."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true/false"
    return {dict: "an object", list: "a list", str: "a string"}.get(type(value), "a number")


def _show(value) -> str:
    """A parsed value as JSON writes it, shortened; containers by their kind."""
    if isinstance(value, dict | list):
        return _kind(value)
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "…"


def _is_number(value) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return "not a number"
    if isinstance(value, int) and abs(value) > 1.7976931348623157e308:
        return "beyond float64's range"
    return None


def _is_whole(value) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        return "not a whole number >= 0"
    return None


def _nested(value, name: str, levels: int, leaf: Callable) -> None:
    """Check that ``value`` is lists ``levels`` deep (iteratively: any depth of nesting
    is refused, never recursed into) whose entries pass ``leaf`` (which returns the
    problem, or None)."""
    stack = [(value, name, 0)]
    while stack:
        item, where, level = stack.pop()
        if level < levels:
            if not isinstance(item, list):
                raise ValueError(f"{where} is {_show(item)}, expected a list")
            stack.extend((entry, f"{where}[{i}]", level + 1)
                         for i, entry in reversed(list(enumerate(item))))
        elif isinstance(item, dict | list):
            raise ValueError(f"{where} is {_kind(item)}, expected a number")
        elif (problem := leaf(item)) is not None:
            raise ValueError(f"{where} is {_show(item)}, {problem}")


def _check_fields(doc: dict) -> None:
    """Each field of its JSON type (shapes are the model's to check)."""
    for key in ("n_modes", "n_states", "n_inputs", "n_outputs"):
        if _is_whole(doc[key]) is not None:
            raise ValueError(f"{key} must be a whole number, got {_show(doc[key])}")
    for key in ("output_lags", "input_lags"):
        if doc[key] is not None and _is_whole(doc[key]) is not None:
            raise ValueError(f"{key} must be a whole number or null, got {_show(doc[key])}")
    if not isinstance(doc["affine"], bool):
        raise ValueError(f"affine must be true or false, got {_show(doc['affine'])}")
    for key in ("state_names", "input_names", "output_names"):
        if not isinstance(doc[key], list) or not all(isinstance(v, str) for v in doc[key]):
            raise ValueError(f"{key} must be a list of strings, got {_show(doc[key])}")
    for key, levels in _ARRAYS.items():
        if key in doc:
            _nested(doc[key], key, levels, _is_number)
    regions = doc["regions"]
    if not isinstance(regions, list) or not all(
            isinstance(r, dict) and {"H", "h"} <= set(r) for r in regions):
        raise ValueError("regions must be a list of objects with 'H' and 'h'")
    for i, region in enumerate(regions):
        _nested(region["H"], f"region {i} H", 2, _is_number)
        _nested(region["h"], f"region {i} h", 1, _is_number)
    envelope = doc["envelope"]
    if not isinstance(envelope, dict):
        raise ValueError(f"envelope must be an object, got {_show(envelope)}")
    missing = [k for k in ("lower", "upper", "padding") if k not in envelope]
    if missing:
        raise ValueError(f"the envelope lacks field(s) {missing}")
    for key in ("lower", "upper"):
        _nested(envelope[key], f"envelope {key}", 1, _is_number)
    padding = envelope["padding"]
    if padding is not None and (_is_number(padding) is not None or padding < 0):
        raise ValueError(f"envelope padding must be a number >= 0 or null, got "
                         f"{_show(padding)}")
    for key in ("mode_regions", "dropped_modes"):
        _nested(doc[key], key, 2, _is_whole)
    if not isinstance(doc["source"], dict):
        raise ValueError(f"source must be an object, got {_show(doc['source'])}")


def _check_regions(ss) -> None:
    """Each region holds a ball inside the envelope, no two overlap there (they may share a
    boundary), by the Chebyshev balls of `polyhedra`, and together they cover it
    (`_uncovered`)."""
    box = Box(*ss.envelope)
    units = [box.to_unit(H, h) for H, h in ss.regions]
    centres = []
    for i, (H, h) in enumerate(ss.regions):
        if not len(h) and ss.n_modes > 1:
            raise ValueError(f"region {i} has no rows: all of z, which overlaps the other "
                             f"{ss.n_modes - 1} regions")
        radius, centre = chebyshev_ball(*units[i])
        if radius <= EMPTY_RADIUS:
            raise ValueError(f"region {i} is empty inside the envelope (it holds no ball "
                             f"of radius {EMPTY_RADIUS:g} half-widths), so it is no mode")
        centres.append(centre)
    for i, j in combinations(range(ss.n_modes), 2):
        radius, _ = chebyshev_ball(np.vstack([units[i][0], units[j][0]]),
                                   np.concatenate([units[i][1], units[j][1]]))
        if radius > EMPTY_RADIUS:
            raise ValueError(f"regions {i} and {j} overlap inside the envelope (they share a "
                             f"ball of radius {radius:.3g} half-widths), so the regions no "
                             f"longer partition it")
    point = _uncovered(units, centres)
    if point is not None:
        z = box.centre + box.half_width * point
        shown = ", ".join(f"{name} = {v:.6g}"
                          for name, v in zip([*ss.state_names, *ss.input_names], z,
                                             strict=True))
        raise ValueError(f"the regions do not cover the envelope: the point {shown} inside "
                         f"it lies in no region, so the regions no longer partition it")


#: Points drawn at random in the envelope by the coverage check (`_uncovered`).
COVERAGE_SAMPLES = 4096
#: How far beyond a region's boundary (in half-widths) the coverage check looks for the
#: next region; a point counts as inside a region within a tenth of it.
COVERAGE_STEP = 1e-6


def _uncovered(units: list[tuple[np.ndarray, np.ndarray]], centres: list[np.ndarray],
               seed: int = 0) -> np.ndarray | None:
    """A point of the box [−1, 1]ⁿ (the envelope in its own coordinates) inside no region
    {z̃ : H̃ z̃ ≤ h̃} of `units`, or None if none is found.

    A sampled check: `COVERAGE_SAMPLES` seeded uniform points of the box, and for each
    region the points `COVERAGE_STEP` beyond its boundary along rays from its Chebyshev
    centre (in `centres`) in the direction of each of its rows and of each coordinate
    both ways. Where two regions meet, the point beyond one lies in the other, so a gap
    left between regions (a region shrunk or removed) is found wherever such a ray crosses
    it; a gap narrower than the step, or that no ray and no sample meets, is not.
    """
    if any(not len(ht) for _, ht in units):  # a region of no rows is all of z
        return None
    p = units[0][0].shape[1]
    rng = np.random.default_rng(seed)
    points = [rng.uniform(-1.0, 1.0, (COVERAGE_SAMPLES, p))]
    for (Ht, ht), centre in zip(units, centres, strict=True):
        rays = np.vstack([Ht, np.eye(p), -np.eye(p)])
        rays /= np.maximum(np.linalg.norm(rays, axis=1, keepdims=True), 1e-300)
        slack = ht - Ht @ centre
        speed = Ht @ rays.T  # (rows, rays)
        with np.errstate(divide="ignore", invalid="ignore"):
            exit_ = np.where(speed > 0, slack[:, None] / speed, np.inf).min(axis=0)
        beyond = centre + (np.minimum(exit_, 4.0) + COVERAGE_STEP)[:, None] * rays
        points.append(beyond)
    z = np.vstack(points)
    z = z[np.all(np.abs(z) < 1.0, axis=1)]
    covered = np.zeros(len(z), bool)
    for Ht, ht in units:
        covered |= np.all(z @ Ht.T <= ht + COVERAGE_STEP / 10, axis=1)
    return z[np.argmin(covered)] if not covered.all() else None
