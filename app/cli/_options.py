"""Command-line options shared by ``fly``, ``ground`` and ``agent``: the mission config, the
broker, the team's size and the built-in simulator's ports, checked like the config file.

Adding the options imports nothing heavy (``standoff --help`` builds every parser); the checks
import what they need when they run."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from app.errors import ConfigError

if TYPE_CHECKING:
    from app.config.mission import MissionConfig

DEFAULT_CONFIG = "hil"


def add_mission_options(p: argparse.ArgumentParser, broker_help: str) -> None:
    """CONFIG, --broker, --vehicles and --base-port."""
    p.add_argument(
        "config",
        nargs="?",
        default=DEFAULT_CONFIG,
        help=(
            f"mission config: a path, or the name of a shipped one (standoff configs lists "
            f"them; default: {DEFAULT_CONFIG})"
        ),
    )
    p.add_argument("--broker", metavar="URL", help=broker_help)
    p.add_argument("--vehicles", type=int, help="number of vehicles (default: the config's)")
    p.add_argument(
        "--base-port", type=int, help="built-in simulator's first UDP port (default: the config's)"
    )


def with_overrides(config: MissionConfig, args: argparse.Namespace) -> MissionConfig:
    """The config with the command line's --vehicles, --speedup, --seed and --base-port (those
    the command has), validated like the file itself (ConfigError naming the option's field)."""
    from app.config import validate_config
    from app.config.mission import MissionConfig

    sim = {
        key: value
        for key in ("speedup", "seed", "base_port")
        if (value := getattr(args, key, None)) is not None
    }
    vehicles = getattr(args, "vehicles", None)
    if not sim and vehicles is None:
        return config
    raw = config.model_dump()
    raw["sim"].update(sim)
    if vehicles is not None:
        raw["vehicles"] = vehicles
    return validate_config(raw, MissionConfig, "command line")


def broker_url(args: argparse.Namespace, config: MissionConfig) -> str:
    """The broker to use: ``--broker``, else the config's ``bus``; checked before any I/O."""
    from app.adapters.bus import BrokerUrl

    url: str | None = args.broker or config.bus
    if url is None:
        raise ConfigError(
            "no MQTT broker: give --broker mqtt://host:port (or 'bus' in the config);"
            " the processes of a mission meet on a broker"
        )
    BrokerUrl.parse(url)  # raises BusUrlError (a ConfigError) with the reason
    return url
