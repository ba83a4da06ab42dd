"""Speed of the dataset generators.

The simulated systems are integrated by compiled kernels, so that a test or an
example can draw a fresh record in a fraction of a second. This script prints,
for every generator of :mod:`sknlss.datasets` with its defaults, the median
time of five draws (random states 1-5) after a first draw that compiles the
kernels.

Run: ``python benchmarks/bench_datasets.py``
"""

import time

import numpy as np

from sknlss.datasets import (make_bouc_wen, make_cascaded_tanks, make_closed_loop_drive,
                             make_duffing, make_pnlss_reference, make_wiener_hammerstein)

GENERATORS = (make_cascaded_tanks, make_wiener_hammerstein, make_duffing, make_bouc_wen,
              make_closed_loop_drive, make_pnlss_reference)


def main():
    print(f"{'generator':28s}{'median of 5 draws':>20s}")
    for make in GENERATORS:
        make(random_state=0)
        times = []
        for seed in range(1, 6):
            start = time.perf_counter()
            make(random_state=seed)
            times.append(time.perf_counter() - start)
        print(f"{make.__name__:28s}{1e3 * np.median(times):17.1f} ms", flush=True)


if __name__ == "__main__":
    main()
