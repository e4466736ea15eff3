"""Benchmarks: commands that print measured figures (run with ``python -m benchmarks.NAME``).

They run the app in their own process, so they take the command line's one BLAS thread
(``app.cli._blas``) before anything loads numpy: what they measure is what ``standoff`` runs."""

from app.cli import _blas  # noqa: F401
