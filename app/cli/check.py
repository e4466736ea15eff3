"""``standoff check CONFIG``: validate a mission file and print the plan, without flying.

The plan is what ``standoff fly`` would do with the file: the vehicles with their MAVLink
system ids, URLs and ports, the altitudes, the bus, the observations, the stages and their
thresholds, the end time, and the parameters each autopilot adapter reads, sets (and restores
at the end) before take-off. A bad file is a one-line reason and exit code 2.
"""

from __future__ import annotations

import argparse

ORDER = 11


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from app.cli._options import add_mission_options

    p = subparsers.add_parser(
        "check",
        help="validate a mission file and print its plan, without flying",
        description=(
            "Validate a mission file and print what standoff fly would do with it: vehicles, "
            "system ids, URLs and ports, stages, and the parameters it checks and sets on each "
            "autopilot. Exits 2 with a one-line reason for a bad file."
        ),
    )
    add_mission_options(p, "MQTT broker the mission would use (default: the config's 'bus')")
    p.add_argument("--connect", nargs="+", metavar="URL", help="external vehicles' URLs")
    p.add_argument(
        "--simulator",
        action="store_true",
        help="as standoff fly --simulator: the built-in simulator with the file's adapter",
    )
    p.add_argument("--speedup", type=float, help="built-in simulator speed-up factor")
    p.add_argument("--seed", type=int, help="built-in simulator's random seed")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.cli._options import with_overrides
    from app.compose.plan_text import describe_plan
    from app.config import load_config, resolve_config
    from app.config.mission import MissionConfig
    from app.config.plan import build_plan
    from app.errors import ConfigError

    config = with_overrides(load_config(args.config, MissionConfig), args)
    if args.simulator:
        if args.connect:
            raise ConfigError("--simulator and --connect exclude each other")
        from app.cli.fly import on_the_simulator

        config = on_the_simulator(config)
    plan = build_plan(config)
    try:
        source = str(resolve_config(args.config))
    except ConfigError:
        source = str(args.config)
    print(describe_plan(plan, args.connect or (), args.broker, args.base_port, source))
    return 0
