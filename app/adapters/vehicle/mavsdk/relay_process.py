"""The mission's MAVLink relays in a process of their own, apart from the mission's interpreter.

In a thread of the mission's process, every datagram waited for Python's interpreter lock
while the agents stepped: with twenty vehicles at 1x, a frame the simulator sent on time (99 %
within 11 ms, seen on the loopback interface) was read by the relay thread 150 ms late in one
case of ten and up to 0.3 s late, and the setpoints waited as long on the way back. With three
vehicles the wait was a few milliseconds. A process of its own has a lock of its own.

The parent (``RelayProcess``, an async context manager) starts::

    python -m app.adapters.vehicle.mavsdk.relay_process

and writes one JSON line to its standard input: the relays (``RelaySpec``) and the .tlog of each
vehicle. The process opens them and answers on its standard output, one JSON line each:
``{"link": {"app_url": ..., "description": ...}}`` per relay, in order, then ``{"ready": true}``;
or ``{"error": ...}`` (a vehicle port that cannot be bound, named) and exits with 2. It relays
until its standard input closes (the parent leaves its block, or the parent has gone, however
it ended), then writes ``{"counters": [...]}`` and exits. Its log lines (``LEVEL message`` on
standard error) are logged again in the parent, at their level.

It runs in a session of its own, as the built-in simulator does: a Ctrl-C in the terminal
reaches the mission alone, which puts every vehicle in hold through the relays before it closes
them.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Self

from app.adapters.tlog import TlogRecorder
from app.adapters.vehicle.mavsdk.relay import MavlinkRelay
from app.adapters.vehicle.mavsdk.urls import UdpEndpoint
from app.errors import LinkError

log = logging.getLogger(__name__)

#: how long the relays may take to open, and to close once told
START_TIMEOUT_S: Final = 20.0
STOP_TIMEOUT_S: Final = 5.0


@dataclass(frozen=True, slots=True)
class RelaySpec:
    """One relay as ``MavlinkRelay`` takes it: the vehicle's connection, the ground station's
    endpoint and this connection's shift of it (``gcs_index``), the vehicles expected on it."""

    vehicle: UdpEndpoint
    gcs: UdpEndpoint | None = None
    gcs_index: int = 0
    system_ids: frozenset[int] = frozenset()
    name: str = "relay"

    def to_json(self) -> dict[str, Any]:
        return {
            "vehicle": _endpoint_json(self.vehicle),
            "gcs": None if self.gcs is None else _endpoint_json(self.gcs),
            "gcs_index": self.gcs_index,
            "system_ids": sorted(self.system_ids),
            "name": self.name,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RelaySpec:
        gcs = data["gcs"]
        return cls(
            vehicle=_endpoint(data["vehicle"]),
            gcs=None if gcs is None else _endpoint(gcs),
            gcs_index=int(data["gcs_index"]),
            system_ids=frozenset(int(s) for s in data["system_ids"]),
            name=str(data["name"]),
        )

    def relay(self, recorder: TlogRecorder | None) -> MavlinkRelay:
        return MavlinkRelay(
            self.vehicle,
            recorder=recorder,
            gcs=self.gcs,
            gcs_index=self.gcs_index,
            system_ids=self.system_ids,
            name=self.name,
        )


def _endpoint_json(endpoint: UdpEndpoint) -> dict[str, Any]:
    return {"mode": endpoint.mode, "host": endpoint.host, "port": endpoint.port}


def _endpoint(data: Mapping[str, Any]) -> UdpEndpoint:
    return UdpEndpoint(data["mode"], str(data["host"]), int(data["port"]))


@dataclass(frozen=True, slots=True)
class RelayedLink:
    """What one relay gives the app: the URL its MAVSDK opens, and a line for the operator."""

    app_url: str
    description: str


class RelayProcess:
    """The relays ``specs`` run in a process of their own while the ``async with`` block lasts;
    ``links`` (in the order of ``specs``) once it is entered. ``tlogs``: system id -> the path
    of its .tlog (none: nothing recorded). A relay that cannot open raises ``LinkError`` naming
    it. ``counters``: what each relay passed on, once the block has closed."""

    def __init__(
        self,
        specs: Sequence[RelaySpec],
        tlogs: Mapping[int, Path] | None = None,
        *,
        start_timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        self._specs = list(specs)
        self._tlogs = dict(tlogs or {})
        self._start_timeout_s = start_timeout_s
        self._proc: asyncio.subprocess.Process | None = None
        self._stack: AsyncExitStack | None = None
        self._closing = False
        self._ended = asyncio.Event()  # the process has ended and that is said
        self.links: list[RelayedLink] = []
        self.counters: list[dict[str, int]] = []

    async def __aenter__(self) -> Self:
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            __name__,
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
            start_new_session=True,
        )
        self._proc = proc
        try:
            await self._start()
        except BaseException:
            await self._stop()
            raise
        async with AsyncExitStack() as stack:
            group = await stack.enter_async_context(asyncio.TaskGroup())
            group.create_task(self._forward_log(), name="relay-process-log")
            group.create_task(self._watch(), name="relay-process-watch")
            stack.push_async_callback(self._stop)  # first on the way out: the tasks then end
            self._stack = stack.pop_all()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        stack, self._stack = self._stack, None
        if stack is not None:
            await stack.aclose()

    @property
    def pid(self) -> int:
        """The relay process's id (for the operator: where its relays run)."""
        proc, _, _ = self._pipes()
        return proc.pid

    def _pipes(
        self,
    ) -> tuple[asyncio.subprocess.Process, asyncio.StreamWriter, asyncio.StreamReader]:
        """The process, its standard input and its standard output."""
        proc = self._proc
        if proc is None or proc.stdin is None or proc.stdout is None:
            raise RuntimeError("RelayProcess used outside its 'async with' block")
        return proc, proc.stdin, proc.stdout

    async def _start(self) -> None:
        _, stdin, _ = self._pipes()
        request = {
            "relays": [spec.to_json() for spec in self._specs],
            "tlogs": {str(s): str(p) for s, p in self._tlogs.items()},
        }
        stdin.write(json.dumps(request).encode() + b"\n")
        await stdin.drain()
        try:
            async with asyncio.timeout(self._start_timeout_s):
                while True:
                    answer = await self._answer()
                    if "link" in answer:
                        self.links.append(RelayedLink(**answer["link"]))
                    elif "error" in answer:
                        raise LinkError(str(answer["error"]))
                    elif answer.get("ready"):
                        return
        except TimeoutError as exc:
            raise LinkError(
                f"the MAVLink relays did not open within {self._start_timeout_s} s"
            ) from exc

    async def _answer(self) -> dict[str, Any]:
        """The process's next line on standard output, as JSON; its end is an error that says
        why (the last lines of its log)."""
        proc, _, stdout = self._pipes()
        line = await stdout.readline()
        if not line:
            code = await proc.wait()
            err = b"" if proc.stderr is None else await proc.stderr.read()
            lines = err.decode(errors="replace").strip().splitlines()
            tail = " | ".join(text.partition(" ")[2] or text for text in lines[-3:])
            raise LinkError(
                f"the MAVLink relay process ended (exit code {code}): {tail or 'no output'}"
            )
        answer: dict[str, Any] = json.loads(line)
        return answer

    async def _forward_log(self) -> None:
        """The process's log lines (``LEVEL message``), logged here at their level."""
        proc = self._proc
        if proc is None or proc.stderr is None:
            return
        while line := await proc.stderr.readline():
            text = line.decode(errors="replace").rstrip()
            level_name, _, message = text.partition(" ")
            level = logging.getLevelNamesMapping().get(level_name)
            if level is None:  # not one of its own lines (a traceback)
                level, message = logging.ERROR, text
            log.log(level, "relay process: %s", message)

    async def _watch(self) -> None:
        """Say so when the process ends before the mission lets it go: every vehicle behind
        it falls silent (the links report the loss)."""
        proc, _, _ = self._pipes()
        code = await proc.wait()
        if not self._closing:
            log.error(
                "the MAVLink relay process ended on its own (exit code %s): the vehicles "
                "relayed through it are silent from now on",
                code,
            )
        self._ended.set()

    async def wait(self) -> int | None:
        """Until the process has ended (and, ended on its own, that is logged): its exit code."""
        await self._ended.wait()
        return self._proc.returncode if self._proc is not None else None

    async def _stop(self) -> None:
        proc = self._proc
        if proc is None:
            return
        self._closing = True
        if proc.stdin is not None and not proc.stdin.is_closing():
            proc.stdin.close()
        try:
            async with asyncio.timeout(STOP_TIMEOUT_S):
                if proc.stdout is not None:
                    while line := await proc.stdout.readline():
                        with contextlib.suppress(ValueError):
                            answer = json.loads(line)
                            if isinstance(answer, dict) and "counters" in answer:
                                self.counters = list(answer["counters"])
                await proc.wait()
        except TimeoutError:
            log.error("the MAVLink relay process did not stop within %s s; killed", STOP_TIMEOUT_S)
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()


# ---- the process ---------------------------------------------------------------------------


def _say(answer: Mapping[str, Any]) -> None:
    """One answer line to the mission; none when the mission is gone (killed outright: its end
    of the pipe is closed), and nothing more on the way out either."""
    try:
        sys.stdout.write(json.dumps(answer) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


class _EndOfInput(asyncio.Protocol):
    def __init__(self, done: asyncio.Event) -> None:
        self._done = done

    def connection_lost(self, exc: Exception | None) -> None:
        self._done.set()


async def serve(specs: Iterable[RelaySpec], tlogs: Mapping[int, Path]) -> int:
    """Open the relays, say where they are, relay until standard input closes."""
    specs = list(specs)
    loop = asyncio.get_running_loop()
    done = asyncio.Event()
    watch, _ = await loop.connect_read_pipe(lambda: _EndOfInput(done), sys.stdin)
    relays: list[MavlinkRelay] = []
    try:
        async with AsyncExitStack() as stack:
            recorder = stack.enter_context(TlogRecorder(dict(tlogs))) if tlogs else None
            try:
                for spec in specs:
                    relay = await stack.enter_async_context(spec.relay(recorder))
                    relays.append(relay)
                    _say({"link": {"app_url": relay.app_url, "description": relay.describe()}})
            except LinkError as exc:
                _say({"error": str(exc)})
                return 2
            _say({"ready": True})
            await done.wait()
        _say({"counters": [dataclasses.asdict(r.counters) for r in relays]})
        return 0
    finally:
        watch.close()


def main() -> int:
    logging.basicConfig(stream=sys.stderr, level=logging.INFO, format="%(levelname)s %(message)s")
    request = json.loads(sys.stdin.readline() or "{}")
    specs = [RelaySpec.from_json(s) for s in request.get("relays", [])]
    tlogs = {int(s): Path(p) for s, p in request.get("tlogs", {}).items()}
    return asyncio.run(serve(specs, tlogs))


if __name__ == "__main__":
    sys.exit(main())
