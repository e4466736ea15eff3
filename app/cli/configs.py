"""``standoff configs [NAME]``: the mission and scenario files that come with the package."""

import argparse

ORDER = 60


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = subparsers.add_parser(
        "configs",
        help="list the shipped mission and scenario files, or print one to copy and edit",
        description=(
            "With no NAME: list the config files that come with standoff, one line each: its "
            "name, the command that takes it and what it is. With NAME: print that file, e.g. "
            "'standoff configs hil > my-mission.toml', edit it and fly it with "
            "'standoff fly my-mission.toml'."
        ),
    )
    p.add_argument("name", nargs="?", metavar="NAME", help="the file to print (e.g. hil, sim-a)")
    p.set_defaults(handler=run)


def command_for(raw: object) -> str:
    """The command a config file is for: the first whose schema it validates against."""
    from pydantic import BaseModel, ValidationError

    from app.config.estimator import EstimatorConfig
    from app.config.mission import MissionConfig
    from app.config.scenario import EstimationScenarioConfig, ScenarioConfig
    from app.config.simulator import SitlScenario

    kinds: tuple[tuple[str, type[BaseModel]], ...] = (
        ("fly", MissionConfig),
        ("simulate", ScenarioConfig),
        ("sitl --scenario", SitlScenario),
        ("estimate --generate", EstimationScenarioConfig),
        ("estimate --config", EstimatorConfig),
    )
    for command, model in kinds:
        try:
            model.model_validate(raw)
        except (ValidationError, ValueError):
            continue
        return command
    return "?"


def run(args: argparse.Namespace) -> int:
    from app.config.loading import read_config, shipped_configs, shipped_text

    if args.name is not None:
        print(shipped_text(args.name), end="")
        return 0
    rows = [(c.name, command_for(read_config(c.name)[1]), c.description) for c in shipped_configs()]
    name_w = max((len(r[0]) for r in rows), default=0)
    command_w = max((len(r[1]) for r in rows), default=0)
    for name, command, description in rows:
        print(f"{name:<{name_w}}  {command:<{command_w}}  {description}".rstrip())
    return 0
