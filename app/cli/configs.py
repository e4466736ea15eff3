"""``standoff configs [NAME]``: the mission and scenario files that come with the package."""

import argparse

ORDER = 60


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = subparsers.add_parser(
        "configs",
        help="list the shipped mission and scenario files, or print one to copy and edit",
        description=(
            "With no NAME: list the config files that come with standoff (the names that "
            "'standoff fly', 'simulate', 'sitl --scenario' and 'estimate' take), one line each. "
            "With NAME: print that file, e.g. 'standoff configs hil > my-mission.toml', edit it "
            "and fly it with 'standoff fly my-mission.toml'."
        ),
    )
    p.add_argument("name", nargs="?", metavar="NAME", help="the file to print (e.g. hil, sim-a)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.config.loading import shipped_configs, shipped_text

    if args.name is not None:
        print(shipped_text(args.name), end="")
        return 0
    listed = shipped_configs()
    width = max((len(c.name) for c in listed), default=0)
    for config in listed:
        print(f"{config.name:<{width}}  {config.description}".rstrip())
    return 0
