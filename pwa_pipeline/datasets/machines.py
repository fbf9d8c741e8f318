"""Simulated machines with switching physics: a tuning set for structure search.

Three physically different machines, each simulated by a fixed-step integrator much finer
than its sampling period and sampled with a zero-order hold on the input:

- [`make_two_link_arm`][pwa_pipeline.datasets.make_two_link_arm]: a two-link planar arm in a vertical plane,
gravity, Coulomb and
  viscous joint friction (switching on the sign of each joint velocity), torques in, joint
  angles out;
- [`make_two_tank`][pwa_pipeline.datasets.make_two_tank]: two cascaded tanks with an inlet valve that
saturates (shut below
  one command, fully open above another) and an upper tank that overflows;
- [`make_dc_motor`][pwa_pipeline.datasets.make_dc_motor]: a DC motor driving an inertia through a gear with
backlash, behind
  an amplifier with a dead zone, voltage in, motor and load speed out.

Every generator returns a [`Dataset`][pwa_pipeline.datasets.Dataset] of several experiments (lists of arrays,
one per experiment), each experiment drawn from its own random stream, the input a filtered
random multi-level signal that crosses the machine's switching surfaces, the measured
outputs corrupted by Gaussian sensor noise of a realistic size.

Seeds. The same ``seed`` gives the same data, bit for bit. Seeds ``0 … 999``
(`TUNING_SEEDS`) are for tuning estimators and their defaults; seeds from ``1000``
(`REPORTING_FIRST_SEED`) are for reported figures only and are never used while
tuning. Held-out experiments of a seed (``n_test``) come from a random stream
independent of its training experiments, so the two never share an input or a noise draw.
None of these data come from, or are calibrated on, the KUKA KR300 test record.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._typing import Float2D
from .dataset import Dataset, GroundTruth

#: Seeds for tuning estimators on the machines (never reported as results).
TUNING_SEEDS = range(0, 1000)
#: First seed for reported figures; reporting seeds are never used while tuning.
REPORTING_FIRST_SEED = 1000
GRAVITY = 9.81  # m/s²


@dataclass(frozen=True)
class _Part:
    """The training or held-out experiments of one machine, as a generator simulates them:
    inputs, measured and noise-free outputs, switching flags (lists, one array per
    experiment)."""

    u: list[Float2D]
    y: list[Float2D]
    y_clean: list[Float2D]
    flags: dict[str, list[np.ndarray]]
    sample_time: float
    noise_std: np.ndarray
    u_names: list[str]
    y_names: list[str]
    units: dict[str, str]


def _check(n_experiments: int, n_samples: int, noise_std) -> None:
    if int(n_experiments) != n_experiments or n_experiments < 1:
        raise ValueError(f"n_experiments must be an integer >= 1, got {n_experiments!r}")
    if int(n_samples) != n_samples or n_samples < 2:
        raise ValueError(f"n_samples must be an integer >= 2, got {n_samples!r}")
    if noise_std is not None and np.any(np.asarray(noise_std, dtype=float) < 0):
        raise ValueError(f"noise_std must be >= 0, got {noise_std!r}")


def _rng(seed: int, held_out: bool) -> np.random.Generator:
    """The random stream of a seed's training (spawn key 0) or held-out (1) experiments."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(held_out),)))


def multilevel(rng: np.random.Generator, n_experiments: int, n_samples: int, low: np.ndarray,
               high: np.ndarray, hold: tuple[int, int], smooth: float,
               near_zero: float = 0.0, zero_width: np.ndarray | None = None) -> np.ndarray:
    """Filtered random multi-level signals of shape (n_experiments, n_samples, channels).

    Each channel holds a level drawn uniformly in ``[low, high]`` (with probability
    ``near_zero`` uniformly in ``[-zero_width, zero_width]`` instead, to dwell near a dead
    zone) for a random number of samples in ``hold`` (inclusive), then passes through a
    first-order low-pass filter with a time constant of ``smooth`` samples (0: none). Such
    signals excite both slow and fast dynamics and, unlike white noise, let the machine
    settle in a regime long enough for its switching to show.
    """
    low, high = np.atleast_1d(low).astype(float), np.atleast_1d(high).astype(float)
    channels = low.size
    out = np.empty((n_experiments, n_samples, channels))
    for e in range(n_experiments):
        for c in range(channels):
            k = 0
            while k < n_samples:
                length = int(rng.integers(hold[0], hold[1] + 1))
                if zero_width is not None and rng.random() < near_zero:
                    level = rng.uniform(-zero_width[c], zero_width[c])
                else:
                    level = rng.uniform(low[c], high[c])
                out[e, k : k + length, c] = level
                k += length
    if smooth > 0:
        a = np.exp(-1.0 / smooth)
        for k in range(1, n_samples):
            out[:, k] = a * out[:, k - 1] + (1 - a) * out[:, k]
    return out


def _noisy(clean: np.ndarray, std: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return clean + rng.standard_normal(clean.shape) * std


def _package(u: np.ndarray, y_clean: np.ndarray, flags: dict[str, np.ndarray],
             noise_std: np.ndarray, rng: np.random.Generator, sample_time: float,
             u_names: list[str], y_names: list[str], units: dict[str, str]) -> _Part:
    y = _noisy(y_clean, noise_std, rng)
    return _Part(u=list(u), y=list(y), y_clean=list(y_clean),
                 flags={k: list(v) for k, v in flags.items()}, sample_time=sample_time,
                 noise_std=np.asarray(noise_std, dtype=float), u_names=u_names,
                 y_names=y_names, units=units)


def _dataset(name: str, simulate: Callable[..., _Part], n_experiments: int, n_test: int,
             **kwargs) -> Dataset:
    """A machine's [`Dataset`][pwa_pipeline.datasets.Dataset]: ``n_experiments`` training experiments from
    the seed's training stream and ``n_test`` held-out ones from its independent held-out
    stream (none with ``n_test=0``)."""
    train = simulate(n_experiments=n_experiments, held_out=False, **kwargs)
    test = simulate(n_experiments=n_test, held_out=True, **kwargs) if n_test else None
    truth = GroundTruth(
        y_clean_train=train.y_clean, y_clean_test=test.y_clean if test else [],
        flags_train=train.flags, flags_test=test.flags if test else {},
        noise_std=train.noise_std)
    return Dataset(name, train.u, train.y, test.u if test else [], test.y if test else [],
                   train.u_names, train.y_names, truth, train.units, train.sample_time)


# --------------------------------------------------------------------------- two-link arm

#: Parameters of `make_two_link_arm` (SI units: m, kg, kg·m², N·m, N·m·s/rad, rad).
ARM = {
    "l1": 1.0, "lc1": 0.5, "m1": 20.0, "I1": 20.0 * 1.0**2 / 12,
    "lc2": 0.4, "m2": 10.0, "I2": 10.0 * 0.8**2 / 12,
    "viscous": np.array([6.0, 2.0]), "coulomb": np.array([15.0, 6.0]), "v_smooth": 0.02,
    "kp": np.array([120.0, 40.0]), "kd": np.array([20.0, 6.0]),
    "home": np.radians([-90.0, 0.0]), "reference_span": np.radians([50.0, 60.0]),
    "feedforward_span": np.array([20.0, 8.0]), "torque_noise": np.array([0.5, 0.2]),
}


def _arm_acceleration(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """q̈ = M(q)⁻¹ (τ − C(q, q̇) − G(q) − F(q̇)) for arrays of shape (n_experiments, 2)."""
    p = ARM
    c2, s2 = np.cos(q[:, 1]), np.sin(q[:, 1])
    m11 = (p["m1"] * p["lc1"] ** 2 + p["m2"] * (p["l1"] ** 2 + p["lc2"] ** 2
           + 2 * p["l1"] * p["lc2"] * c2) + p["I1"] + p["I2"])
    m12 = p["m2"] * (p["lc2"] ** 2 + p["l1"] * p["lc2"] * c2) + p["I2"]
    m22 = p["m2"] * p["lc2"] ** 2 + p["I2"]
    h = p["m2"] * p["l1"] * p["lc2"] * s2
    coriolis = np.column_stack([-h * (2 * qd[:, 0] * qd[:, 1] + qd[:, 1] ** 2), h * qd[:, 0] ** 2])
    g12 = p["m2"] * p["lc2"] * GRAVITY * np.cos(q[:, 0] + q[:, 1])
    gravity = np.column_stack([(p["m1"] * p["lc1"] + p["m2"] * p["l1"]) * GRAVITY
                               * np.cos(q[:, 0]) + g12, g12])
    friction = p["viscous"] * qd + p["coulomb"] * np.tanh(qd / p["v_smooth"])
    rhs = tau - coriolis - gravity - friction
    det = m11 * m22 - m12**2
    return np.column_stack([(m22 * rhs[:, 0] - m12 * rhs[:, 1]) / det,
                            (m11 * rhs[:, 1] - m12 * rhs[:, 0]) / det])


def make_two_link_arm(n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
                      noise_std: float | None = 0.05, n_test: int = 0,
                      burn_in: int = 20) -> Dataset:
    """A two-link planar arm in a vertical plane: joint torques in, joint angles out, 10 Hz.

    Physics (SI units; q1 from the horizontal, q2 relative to link 1, so (−90°, 0°) hangs
    straight down)::

        M(q) q̈ + C(q, q̇) + G(q) + F(q̇) = τ
        M11 = m1 lc1² + m2 (l1² + lc2² + 2 l1 lc2 cos q2) + I1 + I2
        M12 = m2 (lc2² + l1 lc2 cos q2) + I2,   M22 = m2 lc2² + I2
        C = h [−(2 q̇1 q̇2 + q̇2²), q̇1²],          h = m2 l1 lc2 sin q2
        G = g [(m1 lc1 + m2 l1) cos q1 + m2 lc2 cos(q1+q2), m2 lc2 cos(q1+q2)]
        F_i = b_i q̇_i + F_c,i tanh(q̇_i / v_s)    (viscous + Coulomb friction)

    with l1 = 1 m, lc1 = 0.5 m, m1 = 20 kg, I1 = 1.67 kg·m², lc2 = 0.4 m, m2 = 10 kg,
    I2 = 0.53 kg·m² (links 1 m and 0.8 m), b = (6, 2) N·m·s/rad, F_c = (15, 6) N·m,
    v_s = 0.02 rad/s (the Coulomb term's sign switch, smoothed over ±1°/s so that the
    integrator stays stable; outside that band it is the constant ±F_c of dry friction).

    The applied torque is that of a low-gain joint PD loop plus a feedforward torque,
    ``τ = Kp (q_ref − q) − Kd q̇ + τ_ff`` with Kp = (120, 40) N·m/rad, Kd = (20, 6) N·m·s/rad,
    q_ref a filtered multi-level reference within ±50° and ±60° of the hanging posture
    (held 1–4 s, 0.3 s filter) and τ_ff a filtered multi-level torque within ±20 and ±8 N·m.
    The recorded input is this total torque, measured with Gaussian noise of (0.5, 0.2) N·m,
    as the KUKA KR300 record holds measured motor torques of a robot moving under its own
    position controller: inputs and outputs are correlated through feedback ("closed-loop-ish")
    and the loop, not joint limits, keeps every run bounded. A stiff loop would hide the
    friction and gravity in the controller; this one is soft (the gravity torque is up to
    235 N·m against 120 N·m/rad), so they shape the motion. Joint limits were not used
    because end-stop impacts would add a second, non-smooth switching the KUKA data do not
    show.

    Integration: semi-implicit Euler at 5 ms (20 steps a sample, zero-order hold on τ);
    output q in degrees, sampled every 0.1 s, with Gaussian encoder noise of ``noise_std``
    degrees. Each experiment starts at rest in the hanging posture; the first ``burn_in``
    samples are dropped.

    Parameters
    ----------
    n_experiments : int, default 40
    n_samples : int, default 600
        Samples per experiment (60 s at 10 Hz).
    seed : int, default 0
        Tuning seeds are 0–999, reporting seeds 1000 and above (module docstring).
    noise_std : float or None, default 0.05
        Output noise standard deviation in degrees; None or 0: noise-free outputs (the
        recorded torques stay noisy).
    n_test : int, default 0
        Held-out experiments, from the seed's held-out random stream, independent of its
        training experiments (0: none).
    burn_in : int, default 20

    Returns
    -------
    Dataset
        Inputs ``tau1, tau2`` [N·m], outputs ``q1, q2`` [deg]; flags ``"q1_dot>0"``,
        ``"q1_dot<0"``, ``"q2_dot>0"``, ``"q2_dot<0"``: the joint moves faster than v_s in
        that direction at the sampling instant, so its Coulomb friction is −F_c or +F_c
        (neither: the joint sticks, friction within ±F_c).
    """
    return _dataset("two_link_arm", _two_link_arm, n_experiments, n_test, n_samples=n_samples, seed=seed,
                    noise_std=noise_std, burn_in=burn_in)


def _two_link_arm(n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
                  noise_std: float | None = 0.05, held_out: bool = False,
                      burn_in: int = 20) -> _Part:
    """The experiments of [`make_two_link_arm`][pwa_pipeline.datasets.make_two_link_arm] from the seed's
    training or held-out stream."""
    _check(n_experiments, n_samples, noise_std)
    rng = _rng(seed, held_out)
    p, dt, sub = ARM, 0.1, 20
    total = n_samples + burn_in
    reference = p["home"] + multilevel(rng, n_experiments, total, -p["reference_span"],
                                       p["reference_span"], (10, 40), 3.0)
    feedforward = multilevel(rng, n_experiments, total, -p["feedforward_span"],
                             p["feedforward_span"], (5, 30), 2.0)
    q = np.tile(p["home"], (n_experiments, 1))
    qd = np.zeros_like(q)
    h = dt / sub
    tau = np.empty((n_experiments, total, 2))
    angles, rates = np.empty_like(tau), np.empty_like(tau)
    for k in range(total):
        angles[:, k], rates[:, k] = q, qd
        tau[:, k] = p["kp"] * (reference[:, k] - q) - p["kd"] * qd + feedforward[:, k]
        for _ in range(sub):
            qd = qd + h * _arm_acceleration(q, qd, tau[:, k])
            q = q + h * qd
    tau_measured = _noisy(tau, p["torque_noise"], rng)[:, burn_in:]
    angles, rates = np.degrees(angles[:, burn_in:]), rates[:, burn_in:]
    std = np.zeros(2) if noise_std is None else np.full(2, float(noise_std))
    return _package(tau_measured, angles,
                    {f"q{j + 1}_dot{sign}": (rates[..., j] if sign == ">0" else -rates[..., j])
                     > p["v_smooth"] for j in range(2) for sign in (">0", "<0")},
                    std, rng, dt, ["tau1", "tau2"], ["q1", "q2"],
                    {"tau1": "N·m", "tau2": "N·m", "q1": "deg", "q2": "deg"})


# --------------------------------------------------------------------------- two tanks

#: Parameters of `make_two_tank` (SI units: m², m, m³/s, V).
TANK = {
    "area": (0.0154, 0.0154), "outlet": (5.0e-5, 6.0e-5), "height1": 0.5,
    "q_max": 2.0e-4, "u_shut": 1.0, "u_open": 7.0,
}


def make_two_tank(n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
                  noise_std: float | None = 0.002, n_test: int = 0,
                  burn_in: int = 100) -> Dataset:
    """Two cascaded tanks with a saturating inlet valve and an overflowing upper tank.

    Physics (Torricelli outflow; SI units)::

        s(u)   = clip((u − u_shut) / (u_open − u_shut), 0, 1)     valve opening
        q_in   = q_max s(u)
        A1 ḣ1  = q_in − a1 √(2 g h1) − q_over,   0 ≤ h1 ≤ H1
        A2 ḣ2  = a1 √(2 g h1) − a2 √(2 g h2)

    with A1 = A2 = 0.0154 m² (14 cm diameter), a1 = 5.0e-5 m², a2 = 6.0e-5 m², H1 = 0.5 m,
    q_max = 2.0e-4 m³/s (12 L/min), u_shut = 1 V, u_open = 7 V. The valve is shut below 1 V
    and fully open above 7 V (the saturation); above 5.7 V the upper tank's equilibrium
    (0.82 m at full flow) lies above its rim, so it fills to H1 and the excess q_over spills to the sump
    (the overflow): h1 is clipped at H1 and the lower tank then receives a constant inflow.

    The input is a valve command in volts: a multi-level signal in [0, 10] V held 20–160 s and
    filtered with a 10 s time constant (the valve actuator). Integration: explicit Euler at
    0.1 s (20 steps a sample); levels in metres sampled every 2 s with Gaussian sensor noise
    of ``noise_std`` metres. Each experiment starts with both tanks empty; the first
    ``burn_in`` samples are dropped so that records start at random levels.

    Parameters
    ----------
    n_experiments : int, default 40
    n_samples : int, default 600
        Samples per experiment (20 min at 0.5 Hz).
    seed : int, default 0
        Tuning seeds are 0–999, reporting seeds 1000 and above (module docstring).
    noise_std : float or None, default 0.002
        Level noise standard deviation in metres; None or 0: noise-free.
    n_test : int, default 0
        Held-out experiments (0: none), from the seed's held-out random stream.
    burn_in : int, default 100

    Returns
    -------
    Dataset
        Input ``u`` [V], outputs ``h1, h2`` [m]; flags ``"valve_saturated"`` (command
        outside (u_shut, u_open)) and ``"overflow"`` (upper tank at its rim and spilling).
    """
    return _dataset("two_tank", _two_tank, n_experiments, n_test, n_samples=n_samples, seed=seed,
                    noise_std=noise_std, burn_in=burn_in)


def _two_tank(n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
              noise_std: float | None = 0.002, held_out: bool = False,
                  burn_in: int = 100) -> _Part:
    """The experiments of [`make_two_tank`][pwa_pipeline.datasets.make_two_tank] from the seed's training or
    held-out stream."""
    _check(n_experiments, n_samples, noise_std)
    rng = _rng(seed, held_out)
    p, dt, sub = TANK, 2.0, 20
    total = n_samples + burn_in
    u = multilevel(rng, n_experiments, total, np.array([0.0]), np.array([10.0]), (10, 80), 5.0)
    h = np.zeros((n_experiments, 2))
    levels = np.empty((n_experiments, total, 2))
    overflow = np.zeros((n_experiments, total), dtype=bool)
    step = dt / sub
    a1, a2 = p["outlet"]
    for k in range(total):
        levels[:, k] = h
        q_in = p["q_max"] * np.clip((u[:, k, 0] - p["u_shut"]) / (p["u_open"] - p["u_shut"]),
                                    0.0, 1.0)
        spilling = np.zeros(n_experiments, dtype=bool)
        for _ in range(sub):
            q12 = a1 * np.sqrt(2 * GRAVITY * h[:, 0])
            q2 = a2 * np.sqrt(2 * GRAVITY * h[:, 1])
            h1 = h[:, 0] + step * (q_in - q12) / p["area"][0]
            spilling |= h1 >= p["height1"]
            h = np.column_stack([np.clip(h1, 0.0, p["height1"]),
                                 np.maximum(h[:, 1] + step * (q12 - q2) / p["area"][1], 0.0)])
        overflow[:, k] = spilling
    # a sample overflows when the tank spilled over the interval it ends (h1 at the rim)
    over = np.zeros_like(overflow)
    over[:, 1:] = overflow[:, :-1]
    saturated = (u[..., 0] <= p["u_shut"]) | (u[..., 0] >= p["u_open"])
    std = np.zeros(2) if noise_std is None else np.full(2, float(noise_std))
    b = slice(burn_in, None)
    return _package(u[:, b], levels[:, b],
                    {"valve_saturated": saturated[:, b], "overflow": over[:, b]},
                    std, rng, dt, ["u"], ["h1", "h2"],
                    {"u": "V", "h1": "m", "h2": "m"})


# --------------------------------------------------------------------------- DC motor

#: Parameters of `make_dc_motor` (SI units: V, Ω, N·m/A, kg·m², N·m/rad, rad).
MOTOR = {
    "u_max": 12.0, "dead_zone": 2.5, "R": 4.0, "K": 0.03, "J_m": 2.0e-5, "b_m": 1.0e-6,
    "N": 20.0, "J_l": 5.0e-3, "b_l": 2.0e-3, "k_s": 2.0, "c_s": 0.01,
    "backlash": np.radians(5.0),
}


def make_dc_motor(n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
                  noise_std: tuple[float, float] | float | None = (1.0, 0.05), n_test: int = 0,
                  burn_in: int = 20) -> Dataset:
    """A DC motor behind a dead-zone amplifier, driving an inertia through a gear with
    backlash: voltage in, motor and load speed out, 50 Hz.

    Physics (SI units; inductance neglected, its 1 ms time constant is below the step)::

        v      = dz(sat(u, ±u_max), v_dz)           amplifier: saturation and dead zone
        i      = (v − K ω_m) / R
        J_m ω̇_m = K i − b_m ω_m − τ_s / N
        J_l ω̇_l = τ_s − b_l ω_l
        δ      = θ_m / N − θ_l                      gear play, load side
        τ_s    = k_s (δ − α sign δ) + c_s (ω_m / N − ω_l)   if |δ| > α   (teeth in contact)
               = 0                                          if |δ| ≤ α   (in the gap)

    with dz(v, w) = sign(v) max(|v| − w, 0) and τ_s kept of the sign of δ (the damper does
    not pull teeth together), u_max = 12 V, v_dz = 2.5 V, R = 4 Ω, K = 0.03 N·m/A (= V·s/rad),
    J_m = 2e-5 kg·m², b_m = 1e-6 N·m·s/rad, N = 20, J_l = 5e-3 kg·m², b_l = 2e-3 N·m·s/rad,
    k_s = 2 N·m/rad, c_s = 0.01 N·m·s/rad, backlash half-width α = 5° at the load. Below
    2.5 V the motor gets no voltage (the dead zone); at each reversal the load coasts
    through the 10° gap before the teeth engage again (the backlash).

    The input is a multi-level voltage in ±14 V (so that the amplifier also saturates), two
    levels in five drawn within ±4 V to dwell in and around the dead zone, held 0.1–1 s and
    filtered with a 40 ms time constant. Integration: semi-implicit Euler at 1 ms (20 steps a
    sample); outputs motor speed ω_m and load speed ω_l in rad/s sampled every 20 ms with
    Gaussian noise of ``noise_std`` rad/s (speeds from encoder differences). Each experiment
    starts at rest in the middle of the gap; the first ``burn_in`` samples are dropped.

    Parameters
    ----------
    n_experiments : int, default 40
    n_samples : int, default 600
        Samples per experiment (12 s at 50 Hz).
    seed : int, default 0
        Tuning seeds are 0–999, reporting seeds 1000 and above (module docstring).
    noise_std : float, pair of floats or None, default (1.0, 0.05)
        Noise standard deviation of (ω_m, ω_l) in rad/s; None or 0: noise-free.
    n_test : int, default 0
        Held-out experiments (0: none), from the seed's held-out random stream.
    burn_in : int, default 20

    Returns
    -------
    Dataset
        Input ``u`` [V], outputs ``w_motor, w_load`` [rad/s]; flags ``"dead_zone"`` (|u| ≤
        v_dz: no voltage reaches the motor) and ``"backlash_gap"`` (|δ| ≤ α: no torque
        through the gear).
    """
    return _dataset("dc_motor", _dc_motor, n_experiments, n_test, n_samples=n_samples, seed=seed,
                    noise_std=noise_std, burn_in=burn_in)


def _dc_motor(n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
              noise_std: tuple[float, float] | float | None = (1.0, 0.05),
              held_out: bool = False, burn_in: int = 20) -> _Part:
    """The experiments of [`make_dc_motor`][pwa_pipeline.datasets.make_dc_motor] from the seed's training or
    held-out stream."""
    _check(n_experiments, n_samples, noise_std)
    rng = _rng(seed, held_out)
    p, dt, sub = MOTOR, 0.02, 20
    total = n_samples + burn_in
    u = multilevel(rng, n_experiments, total, np.array([-14.0]), np.array([14.0]), (5, 50),
                   2.0, near_zero=0.4, zero_width=np.array([4.0]))
    w_m = np.zeros(n_experiments)
    w_l, delta = np.zeros_like(w_m), np.zeros_like(w_m)
    speeds = np.empty((n_experiments, total, 2))
    gap = np.empty((n_experiments, total), dtype=bool)
    step = dt / sub
    alpha = p["backlash"]
    for k in range(total):
        speeds[:, k, 0], speeds[:, k, 1] = w_m, w_l
        gap[:, k] = np.abs(delta) <= alpha
        v = np.clip(u[:, k, 0], -p["u_max"], p["u_max"])
        v = np.sign(v) * np.maximum(np.abs(v) - p["dead_zone"], 0.0)
        for _ in range(sub):
            contact = np.abs(delta) > alpha
            spring = p["k_s"] * (delta - alpha * np.sign(delta))
            tau = spring + p["c_s"] * (w_m / p["N"] - w_l)
            tau = np.where(contact & (tau * spring > 0), tau, 0.0)
            current = (v - p["K"] * w_m) / p["R"]
            w_m = w_m + step * (p["K"] * current - p["b_m"] * w_m - tau / p["N"]) / p["J_m"]
            w_l = w_l + step * (tau - p["b_l"] * w_l) / p["J_l"]
            delta = delta + step * (w_m / p["N"] - w_l)
    std = np.zeros(2) if noise_std is None else np.broadcast_to(
        np.asarray(noise_std, dtype=float), (2,)).copy()
    b = slice(burn_in, None)
    return _package(u[:, b], speeds[:, b],
                    {"dead_zone": np.abs(u[:, b, 0]) <= p["dead_zone"], "backlash_gap": gap[:, b]},
                    std, rng, dt, ["u"], ["w_motor", "w_load"],
                    {"u": "V", "w_motor": "rad/s", "w_load": "rad/s"})


#: The machines by name: ``MACHINES[name](n_experiments, n_samples, seed, noise_std, n_test)``.
MACHINES: dict[str, Callable[..., Dataset]] = {
    "two_link_arm": make_two_link_arm,
    "two_tank": make_two_tank,
    "dc_motor": make_dc_motor,
}


def make_machine(name: str, n_experiments: int = 40, n_samples: int = 600, seed: int = 0,
                 n_test: int = 0, **kwargs) -> Dataset:
    """One machine of [`MACHINES`][pwa_pipeline.datasets.MACHINES] by name, with its default noise unless
    ``kwargs`` override it.

    Raises
    ------
    ValueError
        An unknown name (the message lists the known ones).
    """
    if name not in MACHINES:
        raise ValueError(f"unknown machine {name!r}; known: {', '.join(MACHINES)}")
    return MACHINES[name](n_experiments=n_experiments, n_samples=n_samples, seed=seed,
                          n_test=n_test, **kwargs)
