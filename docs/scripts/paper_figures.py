"""Reproduce the paper's figures (Lassoued & Abderrahim 2023) with this library.

    python docs/scripts/paper_figures.py            # writes docs/figures/*.png

Section 5 (the simulated system of Hure & Vašak, eq. 11–13, N = 4000, 30 dB):

- ``sim_local_parameters.png`` (the paper's Fig. 2): local parameter matrices θ_k, two of
  their entries, coloured by DBSCAN cluster, paper setting against the library default, the
  true modes marked;
- ``sim_outputs.png`` (Fig. 4): measured and estimated outputs, samples 1–300 of a fresh
  record, free run of both settings, with the default's error;
- ``sim_switching.png`` (Fig. 5): the true mode and the region each setting's model selects.

Section 6 (the KUKA KR300 robot; skipped with a message when its data are missing):

- ``robot_signals.png`` (Fig. 7–8): the 1,500 first training samples, torques and positions;
- ``robot_outputs.png`` (Fig. 9 and 11): a held-out experiment, measured against the
  paper setting's one-step prediction and the free runs of the default and of the subspace
  baseline;
- ``robot_switching.png`` (Fig. 10): the paper setting's region along that experiment.

Every model is fitted on training data and drawn on data it was not fitted on. About half a
minute on 2 cores.
"""

import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pwa_pipeline import PWARX, SubspaceSS, load_kuka, make_hure_vasak  # noqa: E402
from pwa_pipeline.regressors import build_regressors  # noqa: E402
from pwa_pipeline.scoring import match_submodels  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "figures"
DPI = 110


def save(fig, name: str) -> None:
    fig.savefig(OUT / name, dpi=DPI)
    plt.close(fig)
    print(f"wrote {OUT / name}")


def simulated() -> None:
    train = make_hure_vasak(n_samples=4000, snr_db=30, seed=0)
    test = make_hure_vasak(n_samples=4000, snr_db=30, seed=1)
    models = {
        "paper setting (n_ρ = 18, ε = 0.1, MinPts = 20)":
            PWARX.paper(na=1, nb=1, n_rho=18, eps=0.1, min_pts=20),
        "default": PWARX(na=1, nb=1),
    }
    for model in models.values():
        model.fit(train.u_train[0], train.y_train[0])

    # Fig. 2: θ_k's coefficient of y1(k−1) in output 1 against that of y2(k−1) in output 2,
    # the two entries that tell the four modes apart (0.9/0.7 and 0.6/0.8, eq. 11).
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharex=True, sharey=True)
    for ax, (name, model) in zip(axes, models.items()):
        local, clustering = model.steps_["local_models"], model.steps_["clustering"]
        theta = np.asarray(local.theta_)
        rows = np.flatnonzero(np.all(np.isfinite(theta[:, :, 0]), axis=1))
        labels = clustering.labels_[rows]
        noise = labels < 0
        ax.scatter(theta[rows[noise], 0, 0], theta[rows[noise], 1, 1], s=3, c="0.8",
                   label=f"noise or not clustered ({noise.mean():.0%})")
        for c in np.unique(labels[~noise]):
            sel = labels == c
            ax.scatter(theta[rows[sel], 0, 0], theta[rows[sel], 1, 1], s=3, label=f"cluster {c + 1}")
        ax.scatter(train.truth.thetas[:, 0, 0], train.truth.thetas[:, 1, 1], marker="x", s=80, c="k",
                   label="true modes")
        ax.set_title(f"{name}: {model.n_submodels_} sub-models", fontsize=10)
        ax.set_xlabel("θ_k, output 1, coefficient of y1(k−1)")
        ax.legend(fontsize=7, markerscale=3, loc="upper left")
    axes[0].set_ylabel("θ_k, output 2, coefficient of y2(k−1)")
    axes[0].set_xlim(0.3, 1.3)
    axes[0].set_ylim(0.2, 1.2)
    fig.suptitle("Local parameter matrices of the simulated system (the paper's Fig. 2)")
    fig.tight_layout()
    save(fig, "sim_local_parameters.png")

    # Fig. 4: free runs on a fresh record, samples 1–300.
    k = np.arange(1, 301)
    runs = {name: model.simulate(test.u_train[0], test.y_train[0][:1]) for name, model in models.items()}
    fig, axes = plt.subplots(2, 2, figsize=(10, 5.5), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1]})
    default = runs["default"]
    for j in range(2):
        ax = axes[0, j]
        ax.plot(k, test.y_train[0][k, j], "k", lw=1.2, label="measured")
        for (name, y_sim), style in zip(runs.items(), ("C1--", "C0")):
            ax.plot(k, y_sim[k, j], style, lw=1, label=name.split(" (")[0])
        ax.set_title(f"output y{j + 1}", fontsize=10)
        ax.legend(fontsize=7)
        axes[1, j].plot(k, test.y_train[0][k, j] - default[k, j], "C0", lw=0.8)
        axes[1, j].set_ylabel("error, default", fontsize=8)
        axes[1, j].set_xlabel("sample")
    fig.suptitle("Free run on a fresh record (the paper's Fig. 4)")
    fig.tight_layout()
    save(fig, "sim_outputs.png")

    # Fig. 5: true mode against the region each model selects from the measured regressors,
    # its sub-models paired with the true modes by parameters.
    phi = np.column_stack([test.y_train[0][:-1], test.u_train[0][:-1]])          # eq. (13), samples 1..N−1
    true_mode = test.truth.modes_train[0][1:]
    fig, axes = plt.subplots(3, 1, figsize=(10, 5), sharex=True)
    axes[0].step(k, true_mode[k - 1] + 1, "k", where="mid", lw=1)
    axes[0].set_ylabel("true")
    for ax, (name, model) in zip(axes[1:], models.items()):
        mode_of = match_submodels(model.thetas_, test.truth.thetas)[0]
        region = model.regions_.predict(phi)
        paired = np.where(mode_of[region] >= 0, mode_of[region] + 1, 0)
        agree = np.mean(paired == true_mode + 1)
        ax.step(k, paired[k - 1], "C0" if name == "default" else "C1", where="mid", lw=1)
        ax.set_ylabel(name.split(" (")[0], fontsize=8)
        ax.set_title(f"{name}: the true mode's region on {agree:.1%} of the record",
                     fontsize=9, loc="left")
    for ax in axes:
        ax.set_yticks([0, 1, 2, 3, 4])
        ax.set_ylim(-0.5, 4.5)
    axes[-1].set_xlabel("sample (0: a sub-model paired with no true mode)")
    fig.suptitle("Switching sequence (the paper's Fig. 5)")
    fig.tight_layout()
    save(fig, "sim_switching.png")


def robot() -> None:
    try:
        data = load_kuka()
    except (FileNotFoundError, OSError, ValueError) as exc:
        print(f"robot figures skipped: {exc}", file=sys.stderr)
        return
    u = np.concatenate(data.u_train)[:1500]
    y = np.concatenate(data.y_train)[:1500]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    axes[0].plot(u, lw=0.8)
    axes[0].set_ylabel("torque (Nm)")
    axes[0].legend(data.u_names, fontsize=7, ncol=6)
    axes[1].plot(y, lw=0.8)
    axes[1].set_ylabel("joint position (°)")
    axes[1].legend(data.y_names, fontsize=7, ncol=6)
    axes[1].set_xlabel("sample (10 Hz)")
    fig.suptitle("KUKA KR300: the first 1,500 training samples (the paper's Fig. 7–8)")
    fig.tight_layout()
    save(fig, "robot_signals.png")

    paper = PWARX.paper(na=2, nb=2, n_rho=61, eps=8.0, min_pts=22).fit(data.u_train, data.y_train)
    default = PWARX(na=2, nb=2).fit(data.u_train, data.y_train)
    subspace = SubspaceSS(order=12, horizon=5, refit="simulation").fit(data.u_train, data.y_train)
    u_t, y_t = data.u_test[0], data.y_test[0]
    warm = 10
    one_step = paper.predict(u_t, y_t, n_init=warm)
    free = default.simulate(u_t, y_t[:warm])
    free_ss = subspace.simulate(u_t, y_t[:warm])
    k = np.arange(len(y_t))
    fig, axes = plt.subplots(3, 2, figsize=(10, 8), sharex=True)
    for j, ax in enumerate(axes.flat):
        ax.plot(k, y_t[:, j], "k", lw=1.2, label="measured")
        ax.plot(k, one_step[:, j], "C1--", lw=1,
                label=f"PWA paper setting, one step ({paper.n_submodels_} sub-models)")
        ax.plot(k, free[:, j], "C0", lw=1, label=f"PWA default, free run ({default.n_submodels_} sub-model)")
        ax.plot(k, free_ss[:, j], "C2", lw=1, label="subspace, 12 states, free run")
        ax.set_title(data.y_names[j], fontsize=9)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("sample of the first test experiment")
    fig.suptitle("Robot: measured and estimated joint positions in degrees (the paper's Fig. 9 and 11)")
    fig.tight_layout()
    save(fig, "robot_outputs.png")

    reg = build_regressors([(u_t, y_t)], 2, 2, False)
    region = paper.regions_.predict(reg.phi)
    fig, ax = plt.subplots(figsize=(10, 3))
    ax.step(np.arange(len(region)) + 2, region + 1, where="mid", lw=0.8)
    ax.set_ylabel("sub-model")
    ax.set_xlabel("sample of the first test experiment")
    ax.set_title(f"Robot, paper setting: the region of each sample ({len(np.unique(region))} of "
                 f"{paper.n_submodels_} sub-models used; the paper's Fig. 10)", fontsize=10)
    fig.tight_layout()
    save(fig, "robot_switching.png")


def main() -> None:
    start = time.perf_counter()
    OUT.mkdir(parents=True, exist_ok=True)
    simulated()
    robot()
    print(f"done in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
