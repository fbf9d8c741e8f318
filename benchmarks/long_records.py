"""The structure search on long single records: time, memory and accuracy by length.

``PWARX.auto(na=2, nb=2)`` on one record of the simulated DC motor (``make_machine``,
reporting seed 1000: a record long enough for 1 kHz logs) of 25,000, 100,000 and 400,000
samples, scored by the free-run NRMSE on a test record of 10,000 samples of the same seed,
10-sample warm-up; beside it, up to 100,000 samples, the same search with ``max_rows=None``
(every row and sample), the reference the subsample is measured against. Each fit runs in a
fresh process, so the peak memory is its own. Writes results/long_records.{csv,md}.

Usage: python -m benchmarks.long_records
"""

import json
import subprocess
import sys

import pandas as pd

from benchmarks._common import RESULTS, MachineLoad, describe_load, write_table

LENGTHS = (25_000, 100_000, 400_000)
#: Longest record also searched with max_rows=None.
WHOLE_UP_TO = 100_000
SEED = 1000

_ONE = """
import json, resource, sys, time, warnings
warnings.simplefilter("ignore")
from benchmarks.machines import free_run
from pwa_pipeline import PWARX
from pwa_pipeline.datasets.machines import make_machine
n, whole = int(sys.argv[1]), sys.argv[2] == "whole"
train = make_machine("dc_motor", 1, n, {seed})
test = make_machine("dc_motor", 1, 10_000, {seed} + 1)
t = time.perf_counter()
search = PWARX.auto(na=2, nb=2, **({{"max_rows": None}} if whole else {{}}))
model = search.fit(train.u_train, train.y_train)
seconds = time.perf_counter() - t
print(json.dumps({{"samples": n, "max_rows": str(search.search.max_rows),
                  "fit_seconds": seconds,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "free_run_nrmse": free_run(model, test.u_train, test.y_train),
                  "structures": " | ".join(model.structures_)}}))
""".format(seed=SEED)


def main() -> None:
    load = MachineLoad()
    rows = []
    for n in LENGTHS:
        for variant in (["default", "whole"] if n <= WHOLE_UP_TO else ["default"]):
            out = subprocess.run([sys.executable, "-c", _ONE, str(n), variant], check=True,
                                 capture_output=True, text=True).stdout
            rows.append(json.loads(out.strip().splitlines()[-1]))
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    write_table(table, "long_records")
    with open(RESULTS / "long_records.md", "a") as f:
        f.write(f"\nMachine: {describe_load(load.summary())}.\n")


if __name__ == "__main__":
    main()
