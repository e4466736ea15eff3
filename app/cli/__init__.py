"""The ``standoff`` command line, one module per subcommand (``app.compose`` builds the mission).

Each public module of this package is one subcommand: it defines ``ORDER`` (its place in
``standoff --help``) and ``register(subparsers)``, which adds its parser and sets ``handler``: a
function of the parsed arguments that returns the exit code. Errors of the project's own tree
become a one-line reason on stderr and exit code 2.
"""

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Callable, Sequence

from app import __version__
from app.cli import _blas  # noqa: F401  (before any module that loads numpy)
from app.errors import StandoffError


def _command_modules() -> tuple[str, ...]:
    names = [m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")]
    modules = [importlib.import_module(f"{__name__}.{name}") for name in names]
    return tuple(m.__name__.rsplit(".", 1)[1] for m in sorted(modules, key=lambda m: m.ORDER))


# subcommand modules under app.cli, in the order `standoff --help` lists them
COMMAND_MODULES: tuple[str, ...] = _command_modules()

Handler = Callable[[argparse.Namespace], int]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="standoff",
        description="Cooperative standoff tracking of a moving ground target by fixed-wing UAVs.",
    )
    parser.add_argument("--version", action="version", version=f"standoff {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f"{__name__}.{name}").register(subparsers)
    return parser


def _reasons(group: BaseExceptionGroup[BaseException]) -> list[str] | None:
    """The messages of every exception in a (nested) group if all are ``StandoffError``s."""
    reasons: list[str] = []
    for exc in group.exceptions:
        if isinstance(exc, BaseExceptionGroup):
            inner = _reasons(exc)
            if inner is None:
                return None
            reasons += inner
        elif isinstance(exc, StandoffError):
            reasons.append(str(exc))
        else:
            return None
    return reasons


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)],
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    handler: Handler = args.handler
    try:
        return handler(args)
    except StandoffError as exc:
        print(f"standoff {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BaseExceptionGroup as group:
        # a task group raises what its tasks raised, grouped: when every one is ours, each has
        # a reason worth one line; anything else is a bug and keeps its traceback
        reasons = _reasons(group)
        if reasons is None:
            raise
        for reason in dict.fromkeys(reasons):
            print(f"standoff {args.command}: error: {reason}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"standoff {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
