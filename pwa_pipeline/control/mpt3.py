"""The PWA state-space model as an MPT3 script (MATLAB): `mpt3_script`, what
`PWAStateSpace.to_mpt3` writes.

Names (of signals and states, and the model's source) appear only in comments, each written
by `comment_text` on one line, so no name can become a MATLAB statement."""

import math
from numbers import Real
from pathlib import Path

import numpy as np


def comment_text(text: str) -> str:
    """``text`` as it can stand in a MATLAB comment: every character that is not printable
    (line breaks such as ``\\n``, ``\\r``, U+2028, other control characters) and the
    backslash written with Python's escapes (``\\n``, ``\\u2028``, ``\\\\``), so the
    comment ends where its line does and the name can be read back unambiguously."""
    return "".join(c if c.isprintable() and c != "\\"
                   else c.encode("unicode_escape").decode("ascii") for c in text)


def mpt3_script(ss, path: str | Path | None = None, Ts: float | None = None) -> str:
    """A MATLAB script that builds the model as an MPT3 ``PWASystem`` named ``pwa``.

        Each mode becomes ``LTISystem('A', A, 'B', B, 'C', C, 'D', D, 'f', f, 'g', g,
        'Ts', Ts)`` with its domain set by ``setDomain('xu', Polyhedron('A', H,
        'b', h))`` over (x, u), and ``pwa = PWASystem([sys1, …, sysS])`` joins them, as
        MPT3's documentation of ``PWASystem`` builds a PWA system. The envelope is stored as
        ``z_min`` and ``z_max``. Numbers are written with 17 significant digits.

        Parameters
        ----------
        path : str or Path, optional
            Also write the script there (e.g. ``model_pwa.m``).
        Ts : float, optional
            Sampling time in seconds, a finite number > 0 (a data set's `sample_time`).
            None (unknown): the script sets `Ts = 1` (the model counts samples) and says
            that the sample time is unknown.

        Returns
        -------
        str

        Raises
        ------
        ValueError
            If ``Ts`` is not a finite number > 0.
    """
    if Ts is not None and (isinstance(Ts, bool) or not isinstance(Ts, Real)
                           or not math.isfinite(Ts) or Ts <= 0):
        raise ValueError(f"Ts must be a finite number > 0 (the sampling time), got {Ts!r}")
    def mat(a: np.ndarray) -> str:
        a = np.atleast_2d(a)
        if a.size == 0:
            return f"zeros({a.shape[0]}, {a.shape[1]})"
        return "[" + "; ".join(" ".join(f"{v:.17g}" for v in row) for row in a) + "]"

    lower, upper = ss.envelope
    source = comment_text(", ".join(f"{k}={v}" for k, v in ss.source.items()))
    lines = [
        "% PWA state-space model exported by pwa-pipeline (pwa_pipeline.control)"
        + (f": {source}" if source else ""),
        "%   x(k+1) = A_i x(k) + B_i u(k) + f_i,  y(k) = C_i x(k) + D_i u(k) + g_i,",
        "%   valid where [x(k); u(k)] lies in {z : H_i z <= h_i}.",
        f"% states x: {comment_text(', '.join(ss.state_names))}",
        f"% inputs u: {comment_text(', '.join(ss.input_names))}",
        f"% outputs y: {comment_text(', '.join(ss.output_names))}",
        f"% {ss.n_modes} mode(s); the regions are bounded by the data envelope "
        f"z_min <= [x; u] <= z_max.",
        *(["% sample time unknown: Ts = 1 counts samples; set it to the data's sample "
           "time in seconds"] if Ts is None else []),
        f"Ts = {1.0 if Ts is None else Ts:.17g};",
        f"z_min = {mat(lower[:, None])};",
        f"z_max = {mat(upper[:, None])};",
    ]
    for i in range(ss.n_modes):
        H, h = ss.regions[i]
        k = i + 1
        lines += [
            f"% mode {k} (regions of the fitted model: {ss.mode_regions[i].tolist()})",
            f"A{k} = {mat(ss.A[i])};",
            f"B{k} = {mat(ss.B[i])};",
            f"f{k} = {mat(ss.f[i][:, None])};",
            f"C{k} = {mat(ss.C[i])};",
            f"D{k} = {mat(ss.D[i])};",
            f"g{k} = {mat(ss.g[i][:, None])};",
            f"H{k} = {mat(H) if len(h) else f'zeros(0, {H.shape[1]})'};",
            f"h{k} = {mat(h[:, None]) if len(h) else 'zeros(0, 1)'};",
            f"sys{k} = LTISystem('A', A{k}, 'B', B{k}, 'C', C{k}, 'D', D{k}, "
            f"'f', f{k}, 'g', g{k}, 'Ts', Ts);",
            f"sys{k}.setDomain('xu', Polyhedron('A', H{k}, 'b', h{k}));",
        ]
    lines.append("pwa = PWASystem([" + ", ".join(f"sys{i + 1}" for i in range(ss.n_modes))
                 + "]);")
    text = "\n".join(lines) + "\n"
    if path is not None:
        Path(path).write_text(text, encoding="utf-8")
    return text
