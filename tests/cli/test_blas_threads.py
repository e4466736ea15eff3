"""The command line runs numpy's and scipy's BLAS on one thread (``app.cli._blas``)."""

import os
import subprocess
import sys

PROBE = (
    "import os\n"
    "import app.cli\n"
    "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])\n"
)


def _probe(**env: str) -> list[str]:
    clean = {
        k: v
        for k, v in os.environ.items()
        if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    }
    done = subprocess.run(
        [sys.executable, "-c", PROBE],
        env={**clean, **env},
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    return done.stdout.split()


def test_one_blas_thread_unless_the_user_says_otherwise() -> None:
    # set before numpy loads (OpenBLAS reads it once, when the library is loaded)
    assert _probe() == ["1", "1"]
    assert _probe(OPENBLAS_NUM_THREADS="3") == ["3", "1"]
