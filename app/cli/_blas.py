"""One BLAS thread per process, set before numpy loads (imported first by ``app.cli``).

The mission's matrices are a few rows (the UKF's 6 x 6, the planner's L-BFGS-B), far below
the size where a second BLAS thread pays, but numpy's and scipy's OpenBLAS each start a
worker per core, and the workers spin between calls: on this 2-core machine they took a core
beside the mission and doubled `standoff fly`'s process CPU with the horizon planner (docs/
mission.md "On a machine short of CPU"). A value the user set is kept."""

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
