"""``standoff broker --vehicles N --out DIR``: a mosquitto configuration for a mission's team."""

import argparse
from pathlib import Path

ORDER = 14


def register(subparsers: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    p = subparsers.add_parser(
        "broker",
        help="write a mosquitto configuration for a team: logins, passwords, per-client ACL",
        description=(
            "Write the files a mosquitto broker needs so that each process of a multi-process "
            "mission logs in as its identity (ground, agent-1 .. agent-<N>, and a read-only "
            "observer) and may publish only on its own topics: mosquitto.conf (no anonymous "
            "clients), acl, passwd (hashed) and secrets/<login>.password (0600), one per "
            "process, to pass as --password-file (or [bus] password_file = "
            "'DIR/secrets/{client}.password'), and secrets/mission.key, the team's key for "
            "sealed messages (--mission-key-file). Start the broker with "
            "'mosquitto -c DIR/mosquitto.conf'. Existing files are replaced (new passwords)."
        ),
    )
    p.add_argument("--vehicles", type=int, default=3, help="the team's size (default: 3)")
    p.add_argument("--out", type=Path, required=True, help="the folder to write into")
    p.add_argument(
        "--port", type=int, default=1883, help="the broker's listener port (default: 1883)"
    )
    p.add_argument("--host", help="the address to listen on (default: every address)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from app.adapters.bus.broker_setup import write_team
    from app.errors import ConfigError

    if not 1 <= args.port <= 65535:
        raise ConfigError(f"--port must be 1..65535, got {args.port}")
    try:
        files = write_team(args.out, args.vehicles, port=args.port, host=args.host)
    except ValueError as exc:
        raise ConfigError(f"--vehicles: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"cannot write into {args.out}: {exc}") from exc
    print(f"standoff broker: wrote {files.conf}, {files.acl}, {files.passwd}")
    print(f"  passwords, one per login: {files.directory / 'secrets'}/<login>.password")
    print(f"  start the broker: mosquitto -c {files.conf}")
    print(f"  then each process: --password-file {files.directory}/secrets/{{client}}.password")
    print(
        f"  and to seal every message (an untrusted broker): --mission-key-file {files.mission_key}"
    )
    return 0
