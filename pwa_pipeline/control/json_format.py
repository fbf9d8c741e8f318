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
from pathlib import Path

#: Identifies the JSON document.
SCHEMA = "pwa-pipeline/pwa-state-space"

#: The version of the document this code writes (it reads this and the earlier ones).
SCHEMA_VERSION = 2
#: The versions it reads.
READ_VERSIONS = (1, 2)


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

    Parameters
    ----------
    source : str or Path
    The JSON text, or the path of a file holding it.
    model : callable
    [`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace].

    Raises
    ------
    ValueError
    If the document is not JSON, is of another schema or schema version, lacks a
    field, or a field does not have the shape the others imply (the message names
    the field).
    """
    if isinstance(source, Path) or not str(source).lstrip().startswith("{"):
        source = Path(source).read_text()
    try:
        doc = json.loads(source)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not a JSON document: {exc}") from None
    if not isinstance(doc, dict):
        raise ValueError("the JSON document must be an object")
    if doc.get("schema") != SCHEMA:
        raise ValueError(f"not a PWA state-space document: schema is "
                         f"{doc.get('schema')!r}, expected {SCHEMA!r}")
    if doc.get("schema_version") not in READ_VERSIONS:
        raise ValueError(f"schema version {doc.get('schema_version')!r} is not supported: "
                         f"this version of pwa-pipeline reads versions {list(READ_VERSIONS)}")
    required = ("A", "B", "f", "C", "g", "regions", "envelope", "output_lags",
                "input_lags")
    missing = [k for k in required if k not in doc]
    if missing:
        raise ValueError(f"the document lacks field(s) {missing}")
    envelope = doc["envelope"]
    if not isinstance(envelope, dict) or not {"lower", "upper"} <= set(envelope):
        raise ValueError("envelope must be an object with 'lower' and 'upper'")
    regions = doc["regions"]
    if not isinstance(regions, list) or not all(
            isinstance(r, dict) and {"H", "h"} <= set(r) for r in regions):
        raise ValueError("regions must be a list of objects with 'H' and 'h'")
    ss = model(doc["A"], doc["B"], doc["f"], doc["C"], doc["g"],
             [(r["H"], r["h"]) for r in regions], envelope["lower"], envelope["upper"],
             output_lags=doc["output_lags"], input_lags=doc["input_lags"],
             affine=doc.get("affine", False), D=doc.get("D"),
             input_names=doc.get("input_names"), output_names=doc.get("output_names"),
             state_names=None if doc["output_lags"] is not None else doc.get("state_names"),
             padding=envelope.get("padding"),
             mode_regions=doc.get("mode_regions"), dropped_modes=doc.get("dropped_modes"),
             source=doc.get("source"))
    for key, expected in (("n_modes", ss.n_modes), ("n_states", ss.n_states),
                          ("n_inputs", ss.n_inputs), ("n_outputs", ss.n_outputs)):
        if key in doc and doc[key] != expected:
            raise ValueError(f"{key} is {doc[key]!r} but the matrices give {expected}")
    if "state_names" in doc and doc["state_names"] != ss.state_names:
        raise ValueError(f"state_names {doc['state_names']} do not match the orders and "
                         f"names, which give {ss.state_names}")
    return ss
