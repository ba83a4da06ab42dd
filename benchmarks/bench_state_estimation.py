"""Speed of the NLSS2 state estimation (paper eq. 14).

Prints the time and the peak resident memory of ``estimate_states`` for one
sequence of N samples (a 3-state SISO model, N = 10^4 .. 10^6), with BLAS
limited to 1 and to 2 threads (threadpoolctl; ``estimate_states`` itself runs
its BLAS calls on one thread, so the setting should not matter). The banded
solve costs O(N n^3) time and O(N n^2) memory, so both grow linearly in N.
Each measurement runs in a fresh process, so that the peak memory belongs to
that solve alone.

Run: ``python benchmarks/bench_state_estimation.py``
"""

import json
import subprocess
import sys

_CHILD = """
import json, resource, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
from sknlss._linear._state_estimation import estimate_states

n_samples, threads = int(sys.argv[1]), int(sys.argv[2])
rng = np.random.default_rng(0)
A = np.array([[0.9, 0.2, 0.0], [-0.2, 0.8, 0.1], [0.0, 0.1, 0.5]])
B = rng.standard_normal((3, 1))
C = rng.standard_normal((1, 3))
D = np.zeros((1, 1))
U = rng.standard_normal((n_samples, 1))
Y = rng.standard_normal((n_samples, 1))
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
with threadpool_limits(limits=threads, user_api="blas"):
    start = time.perf_counter()
    estimate_states(U, Y, np.array([0, n_samples]), A, B, C, D, 1.0)
    elapsed = time.perf_counter() - start
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"time": elapsed, "peak_mb": after / 1024, "data_mb": before / 1024}))
"""


def main():
    print(f"{'N':>9} {'BLAS threads':>12} {'time (s)':>9} {'peak RSS (MB)':>14} "
          f"{'RSS before solve (MB)':>22}")
    for n_samples in (10_000, 100_000, 1_000_000):
        for threads in (1, 2):
            out = subprocess.run(
                [sys.executable, "-c", _CHILD, str(n_samples), str(threads)],
                check=True, capture_output=True, text=True,
            ).stdout
            result = json.loads(out)
            print(f"{n_samples:>9} {threads:>12} {result['time']:>9.3f} "
                  f"{result['peak_mb']:>14.0f} {result['data_mb']:>22.0f}", flush=True)


if __name__ == "__main__":
    main()
