"""How a run was made, for its ``summary.json``: the standoff version, the git commit when it
runs from a checkout, the resolved mission config, the seed, the speed-up and the start time.

The summary's layout is numbered by ``app.report.summary.SUMMARY_SCHEMA_VERSION``.
"""

import datetime as dt
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app import __version__

if TYPE_CHECKING:
    from app.config.mission import MissionConfig

# the checkout app/ sits in (there is no .git beside an installed package)
_SOURCE_ROOT = Path(__file__).resolve().parents[2]
_GIT_TIMEOUT_S = 2.0


def git_commit(root: Path = _SOURCE_ROOT) -> tuple[str | None, bool | None]:
    """The commit ``root`` is checked out at and whether tracked files differ from it; (None,
    None) when ``root`` is not a git checkout or git cannot tell (no git, a timeout): never
    raises."""
    if not (root / ".git").exists():
        return None, None
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_S,
            check=True,
        ).stdout.strip()
        status = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_S,
            check=True,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return None, None
    return (commit or None), (bool(status.strip()) if commit else None)


def utc_iso(epoch_s: float) -> str:
    """A wall-clock time (seconds since 1970) as UTC ISO 8601, to the millisecond."""
    return dt.datetime.fromtimestamp(epoch_s, dt.UTC).isoformat(timespec="milliseconds")


def run_block(
    config: "MissionConfig",
    *,
    started_epoch_s: float,
    speedup: float,
    process: str = "fly",
    root: Path = _SOURCE_ROOT,
) -> dict[str, Any]:
    """The summary's ``run`` block. ``speedup``: the rate the mission clock ran at (the
    simulator's speed-up; 1 with real vehicles); ``process``: which command wrote the summary
    (``fly`` or ``ground``)."""
    commit, dirty = git_commit(root)
    return {
        "standoff_version": __version__,
        "git_commit": commit,
        "git_dirty": dirty,
        "process": process,
        "started_utc": utc_iso(started_epoch_s),
        "seed": config.sim.seed,
        "speedup": speedup,
        "config": config.model_dump(mode="json"),
    }
