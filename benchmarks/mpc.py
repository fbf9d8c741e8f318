"""One step of the hybrid MPC (a MILP solve) of horizon 10 on the paper's simulated system.

The default PWARX is fitted on the section 5 system (N = 4000, 30 dB, seed 5) and converted
with ``to_state_space()`` (4 modes, 4 states, 2 inputs, 2 outputs). ``HybridMPC(ss,
horizon=10)`` (default weights and input bounds, move penalty) then solves from ``--solves``
states of a fresh record (seed 6, samples spread over it, those inside the envelope), each
towards a constant reference drawn uniformly in the middle half of each output's training
range. Records the construction time, the median, largest and every solve's wall-clock and
CPU time (HiGHS through ``scipy.optimize.milp``; the CPU time shows what a busy machine
adds), the size of the program and how many solves HiGHS proved optimal. The target is a
median MPC step of at most 1 s.

Writes results/mpc.md and results/mpc.json. Usage: python -m benchmarks.mpc [--solves 20]
"""

import argparse
import statistics
import time

import numpy as np

from benchmarks._common import RESULTS, MachineLoad, Timer, describe_load, write_json
from pwa_pipeline import PWARX, make_hure_vasak
from pwa_pipeline.control import HybridMPC

HORIZON = 10
TARGET_SECONDS = 1.0


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--solves", type=int, default=20)
    parser.add_argument("--horizon", type=int, default=HORIZON)
    args = parser.parse_args(argv)
    load = MachineLoad()
    train = make_hure_vasak(n_samples=4000, snr_db=30.0, seed=5)
    ss = PWARX(na=1, nb=1).fit(train.u_train[0], train.y_train[0]).to_state_space()
    with Timer() as build:
        mpc = HybridMPC(ss, horizon=args.horizon)
    fresh = make_hure_vasak(n_samples=4000, snr_db=30.0, seed=6)
    states = ss.states(fresh.u_train[0], fresh.y_train[0])
    inside = np.flatnonzero(ss.in_envelope(states, fresh.u_train[0][1:]))
    picks = inside[np.linspace(0, len(inside) - 1, args.solves).astype(int)]
    rng = np.random.default_rng(6)
    y_lo, y_hi = train.y_train[0].min(axis=0), train.y_train[0].max(axis=0)
    middle = (y_lo + y_hi) / 2, (y_hi - y_lo) / 4
    seconds, cpu, optimal, modes_used = [], [], 0, []
    for k in picks:
        y_ref = rng.uniform(middle[0] - middle[1], middle[0] + middle[1])
        start = time.process_time()
        plan = mpc.solve(states[k], y_ref)
        cpu.append(time.process_time() - start)
        seconds.append(plan.seconds)
        optimal += plan.optimal
        modes_used.append(len(set(plan.modes.tolist())))
    A = mpc._A
    result = {
        "horizon": args.horizon, "modes": ss.n_modes, "states": ss.n_states,
        "inputs": ss.n_inputs, "outputs": ss.n_outputs,
        "variables": int(A.shape[1]), "binaries": int(mpc._integrality.sum()),
        "constraints": int(A.shape[0]),
        "build_seconds": build.seconds,
        "solves": len(seconds), "median_seconds": statistics.median(seconds),
        "max_seconds": max(seconds), "seconds": seconds,
        "median_cpu_seconds": statistics.median(cpu), "max_cpu_seconds": max(cpu),
        "cpu_seconds": cpu,
        "proved_optimal": optimal, "plans_through_several_modes": sum(u > 1 for u in modes_used),
        "target_seconds": TARGET_SECONDS,
        "machine_load": load.summary(),
    }
    write_json(result, "mpc")
    (RESULTS / "mpc.md").write_text(
        f"Hybrid MPC of horizon {args.horizon} on the paper's simulated system (default PWARX, "
        f"{ss.n_modes} modes, {ss.n_states} states, {ss.n_inputs} inputs, {ss.n_outputs} "
        f"outputs): a MILP of {result['variables']} variables ({result['binaries']} binary) "
        f"and {result['constraints']} constraints, built in {build.seconds:.3f} s.\n\n"
        f"| solves | median s | largest s | median CPU s | largest CPU s | proved optimal | "
        f"plans through several modes | target |\n|---:|---:|---:|---:|---:|---:|---:|---:|\n"
        f"| {len(seconds)} | {result['median_seconds']:.3f} | {result['max_seconds']:.3f} | "
        f"{result['median_cpu_seconds']:.3f} | {result['max_cpu_seconds']:.3f} | "
        f"{optimal}/{len(seconds)} | {result['plans_through_several_modes']} | "
        f"≤ {TARGET_SECONDS:g} s (median) |\n\n"
        f"Machine: {describe_load(result['machine_load'])}.\n")
    print((RESULTS / "mpc.md").read_text())


if __name__ == "__main__":
    main()
