"""Finding config files: a path, or the name of a file shipped as package data; and the
one-line description ``standoff configs`` prints."""

from pathlib import Path

import pytest

from app.config.loading import describe, resolve_config, shipped_dir, shipped_names, shipped_text
from app.errors import ConfigError

CHECKOUT_CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_the_shipped_files_are_the_checkouts_configs_folder():
    assert set(shipped_names()) == {p.stem for p in CHECKOUT_CONFIGS.glob("*.toml")}
    for name in ("hil", "estimator"):
        text = (CHECKOUT_CONFIGS / f"{name}.toml").read_text(encoding="utf-8")
        assert shipped_text(name) == text
        assert (shipped_dir() / f"{name}.toml").read_text(encoding="utf-8") == text


def test_a_name_with_or_without_toml_and_a_path_all_resolve(tmp_path, monkeypatch):
    assert resolve_config("sim-a").read_text() == resolve_config("sim-a.toml").read_text()
    own = tmp_path / "sim-a"  # a file of that path wins over the shipped name
    own.write_text('description = "mine"\n')
    monkeypatch.chdir(tmp_path)
    assert resolve_config("sim-a").read_text() == own.read_text()


def test_an_unknown_name_lists_the_known_ones():
    with pytest.raises(ConfigError, match=r"no config file 'nope' \(known names: .*hil.*\)"):
        resolve_config("nope")
    with pytest.raises(ConfigError, match="no shipped config 'nope'"):
        shipped_text("nope")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('# A comment.\ndescription = "The key wins"\n', "The key wins"),
        (
            "# Fig. 12-like path, e.g. the SIH model. Then more.\nx = 1\n",
            "Fig. 12-like path, e.g. the SIH model.",
        ),
        ("# First line goes on\n# to the second. Not this.\n", "First line goes on to the second."),
        ("# Three processes over MQTT:\n#   mosquitto -p 1883\n", "Three processes over MQTT"),
        ("x = 1\n", ""),
    ],
)
def test_the_description_is_the_first_sentence(text, expected):
    assert describe(text) == expected


def test_a_long_description_is_cut_to_one_short_line():
    got = describe("# " + "word " * 40 + "\n")
    assert "\n" not in got
    assert len(got) <= 100
    assert got.endswith("...")
