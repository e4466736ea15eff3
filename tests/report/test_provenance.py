"""summary.json's ``run`` block: version, commit (from a checkout only), config, seed, speed-up,
start time; it never fails for want of git."""

import subprocess

from app import __version__
from app.config import load_config
from app.config.mission import MissionConfig
from app.report.provenance import git_commit, run_block, utc_iso


def _git(root, *args):
    subprocess.run(["git", "-C", str(root), *args], check=True, capture_output=True)


def test_a_checkout_gives_its_commit_and_whether_it_was_changed(tmp_path):
    _git(tmp_path, "init", "-q")
    (tmp_path / "f.txt").write_text("a\n")
    _git(tmp_path, "add", "f.txt")
    _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "one")
    head = subprocess.run(
        ["git", "-C", str(tmp_path), "rev-parse", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    assert git_commit(tmp_path) == (head, False)
    (tmp_path / "f.txt").write_text("b\n")
    assert git_commit(tmp_path) == (head, True)


def test_no_checkout_gives_none_and_never_raises(tmp_path):
    assert git_commit(tmp_path) == (None, None)
    (tmp_path / ".git").write_text("gitdir: /nowhere\n")  # a broken checkout: git fails
    assert git_commit(tmp_path) == (None, None)


def test_run_block_says_how_the_run_was_made(tmp_path):
    config = load_config("test-short", MissionConfig)
    block = run_block(config, started_epoch_s=86400.25, speedup=3.0, root=tmp_path)
    assert block == {
        "standoff_version": __version__,
        "git_commit": None,
        "git_dirty": None,
        "process": "fly",
        "started_utc": "1970-01-02T00:00:00.250+00:00",
        "seed": config.sim.seed,
        "speedup": 3.0,
        "config": config.model_dump(mode="json"),
    }
    # the config as data: it validates back into the same mission
    assert MissionConfig.model_validate(block["config"]) == config


def test_start_time_is_utc_iso():
    assert utc_iso(0.0) == "1970-01-01T00:00:00.000+00:00"
