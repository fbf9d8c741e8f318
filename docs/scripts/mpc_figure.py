"""Draw the closed-loop figure of the hybrid MPC example in docs/control.md.

    python docs/scripts/mpc_figure.py            # writes docs/figures/mpc_closed_loop.png

The worked example of the page, end to end: the default PWARX identified on the paper's
simulated system (section 5, N = 4000, 30 dB), converted by ``to_state_space()``, written to
JSON and read back, then ``HybridMPC`` of horizon 10 run in closed loop against that model
for 80 samples, from a measured state, towards a reference that visits the four quadrants of
(y1, y2) around (0.5, 0.5), where the system's four modes are. The figure shows the
reference and the closed-loop outputs, the inputs with their bounds, and the active mode.
About half a minute on 2 cores.
"""

import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pwa_pipeline import PWARX, make_hure_vasak  # noqa: E402
from pwa_pipeline.control import HybridMPC, PWAStateSpace  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "figures"
DPI = 110

#: The reference: 20 samples at each point, one in each quadrant (each a reachable
#: equilibrium of the identified model).
TARGETS = [(1.5, 1.0), (-1.0, 1.5), (-1.0, -0.5), (2.0, 0.0)]
HOLD = 20


def main() -> None:
    start = time.perf_counter()
    data = make_hure_vasak(n_samples=4000, snr_db=30.0, seed=0)
    model = PWARX(na=1, nb=1).fit(data.u_train[0], data.y_train[0])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hure_vasak_pwa.json"
        model.to_state_space().to_json(path)
        ss = PWAStateSpace.from_json(path)

    mpc = HybridMPC(ss, horizon=10)
    y_ref = np.repeat(np.array(TARGETS), HOLD, axis=0)
    x0 = ss.states(data.u_train[0], data.y_train[0])[0]
    run = mpc.closed_loop(x0, y_ref, steps=len(y_ref))

    t = np.arange(len(run.y))
    fig, axes = plt.subplots(4, 1, figsize=(10, 8), sharex=True,
                             gridspec_kw={"height_ratios": [2, 2, 2, 1]})
    for j, ax in enumerate(axes[:2]):
        ax.step(t, run.y_ref[:, j], "k--", where="post", lw=1, label="reference")
        ax.plot(t, run.y[:, j], "C0.-", lw=1.2, ms=3, label="closed loop")
        ax.set_ylabel(ss.output_names[j])
        ax.legend(fontsize=7, loc="upper right")
    for q in range(ss.n_inputs):
        axes[2].step(t, run.u[:, q], f"C{q + 1}", where="post", lw=1.2,
                     label=f"{ss.input_names[q]} ∈ [{mpc.u_min[q]:.2f}, {mpc.u_max[q]:.2f}]")
        axes[2].axhline(mpc.u_min[q], color=f"C{q + 1}", lw=0.6, ls=":")
        axes[2].axhline(mpc.u_max[q], color=f"C{q + 1}", lw=0.6, ls=":")
    axes[2].set_ylabel("input")
    axes[2].legend(fontsize=7, loc="upper right")
    axes[3].step(t, run.modes, "C0", where="post", lw=1.2)
    axes[3].set_yticks(range(ss.n_modes))
    axes[3].set_ylim(-0.5, ss.n_modes - 0.5)
    axes[3].set_ylabel("mode")
    axes[3].set_xlabel("sample")
    fig.suptitle(f"Hybrid MPC (horizon {mpc.horizon}, MILP by HiGHS) of the model identified "
                 f"on the paper's simulated system: closed loop", fontsize=10)
    fig.tight_layout()
    OUT.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT / "mpc_closed_loop.png", dpi=DPI)
    plt.close(fig)

    # the plan sees the reference a horizon ahead, so the loop leaves each target early:
    # measure from 3 samples after each change to a horizon before the next
    error = np.abs(run.y - run.y_ref)
    held = [error[i * HOLD + 3:(i + 1) * HOLD - mpc.horizon] for i in range(len(TARGETS))]
    print(f"wrote {OUT / 'mpc_closed_loop.png'}")
    print(f"largest |y - y_ref| from 3 samples after each change to {mpc.horizon} before the "
          f"next: {max(e.max() for e in held):.2e}")
    print(f"solve: median {np.median(run.seconds):.3f} s, largest {run.seconds.max():.3f} s")
    print(f"modes used: {sorted(set(run.modes.tolist()))}")
    print(f"done in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
