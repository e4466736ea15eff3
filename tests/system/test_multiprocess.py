"""The mission as separate processes over a real mosquitto: ``standoff ground`` and ``agent``.

Every process is a real ``python -m app`` subprocess; the ground station runs the built-in
simulator (``--sitl``) on free UDP ports, the broker is a real mosquitto on a free TCP port.
Readiness is read from the processes' own output lines, never waited for with sleeps.

Two runs, each shared by the tests that read it (their faults are apart in time):

- three agents fly a 120 s mission and the broker is restarted mid-track: the run as a whole
  (every agent's clean exit, the run folder, the shutdown) and the restart's own outcome;
- a team of two: SIGTERM to agent 0 while it flies, then Ctrl-C on the ground station (agent 1
  still flying is told to shut down).

The commands refused on bad input run ``main`` in this process (``exit_code_of``); the one with
no broker to reach is a process of its own.
"""

import asyncio
import contextlib
import csv
import itertools
import json
import logging
import math
import signal
import sys
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import pytest_asyncio

from app.adapters.bus import MissionKey, MqttBus, open_bus
from app.cli import main
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from sitl.ports import find_free_udp_base_port
from sitl.px4 import HOLD
from sitl.vehicle import AUTOPILOT_COMPONENT
from tests.support.mosquitto import Mosquitto, refused_port
from tests.support.sitl_fixtures import RawClient

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
OUTAGE_S = 3.0  # how long the broker stays down in the team run (wall time)
# The team run: the team loiters 200 m from the target, gets the tracking command at 5 s,
# gathers and spaces while the target waits (35 s; track from ~40 s), then tracks it as it
# drives 270 m north at 3 m/s, to the end (120 s of mission time, 40 s of wall time).
TEAM_END_S = 120.0
TEAM_STANDBY_EAST_M = -200.0
TEAM_WAIT_S = 35.0
TEAM_LEG_NORTH_M = 270.0
STOP_S = 30.0  # wall time a signalled agent gets to hold its vehicle and leave (1-5 s seen)

# By default the team loiters 350 m from the target, gets the tracking command at 5 s, gathers
# and spaces while the target waits (50 s), then tracks it for 60 s at 3 m/s: 120 s of mission
# time, 40 s of wall time at speed-up 3.
SHORT_MISSION = """
name = "short-mqtt"
vehicles = {vehicles}
radius_m = 90.0
tracking_command_s = 5.0
end_s = {end_s}

[limits]
cruise_speed_m_s = 14.0
min_speed_m_s = 10.0
max_speed_m_s = 18.0
max_accel_m_s2 = 2.0
max_course_rate_rad_s = 0.2

[standby]
east_m = {standby_east_m}
north_m = 0.0
radius_m = 150.0

[target]
kind = "waypoints"
wait_s = {wait_s}
legs = [{{ to_east_m = 0.0, to_north_m = {leg_north_m}, speed_m_s = 3.0, label = "A-B" }}]

[link]
connect_timeout_s = 60.0

[sim]
speedup = 3.0
"""


def write_mission(
    tmp_path: Path,
    vehicles: int = 3,
    end_s: float = 120.0,
    standby_east_m: float = -350.0,
    wait_s: float = 50.0,
    leg_north_m: float = 180.0,
) -> Path:
    path = tmp_path / "short-mqtt.toml"
    text = SHORT_MISSION.format(
        vehicles=vehicles,
        end_s=end_s,
        standby_east_m=standby_east_m,
        wait_s=wait_s,
        leg_north_m=leg_north_m,
    )
    path.write_text(text, encoding="utf-8")
    return path


@dataclass
class Standoff:
    """One ``python -m app ...`` subprocess: stdout read line by line, stderr to a file."""

    proc: asyncio.subprocess.Process
    stderr_path: Path
    lines: list[str] = field(default_factory=list)

    async def wait_for(self, needle: str, timeout_s: float) -> str:
        """Read stdout until a line containing ``needle``; fail with what was seen otherwise."""
        assert self.proc.stdout is not None
        try:
            async with asyncio.timeout(timeout_s):
                while True:
                    raw = await self.proc.stdout.readline()
                    if not raw:
                        pytest.fail(f"exited before {needle!r}:\n{self.transcript()}")
                    line = raw.decode(errors="replace").rstrip()
                    self.lines.append(line)
                    if needle in line:
                        return line
        except TimeoutError:
            pytest.fail(f"no {needle!r} within {timeout_s} s:\n{self.transcript()}")

    async def finish(self, timeout_s: float) -> int:
        """Wait for the process to exit (reading the rest of stdout); its exit code."""
        try:
            async with asyncio.timeout(timeout_s):
                out, _ = await self.proc.communicate()
        except TimeoutError:
            pytest.fail(f"still running after {timeout_s} s:\n{self.transcript()}")
        self.lines += out.decode(errors="replace").splitlines()
        assert self.proc.returncode is not None
        return self.proc.returncode

    def stdout(self) -> str:
        return "\n".join(self.lines)

    def stderr(self) -> str:
        return self.stderr_path.read_text(errors="replace") if self.stderr_path.exists() else ""

    def transcript(self) -> str:
        return f"--- stdout\n{self.stdout()}\n--- stderr\n{self.stderr()[-3000:]}"


def one_line(text: str) -> str:
    """The only line of ``text`` (a one-line error), failing when there are more or none."""
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


@contextlib.asynccontextmanager
async def standoff(*args: str, stderr_path: Path) -> AsyncIterator[Standoff]:
    """Start ``python -m app ARGS``; on the way out, stop it (SIGINT, then kill) if it runs."""
    with stderr_path.open("wb") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "app",
            *args,
            cwd=REPO,
            stdout=asyncio.subprocess.PIPE,
            stderr=err,
        )
        try:
            yield Standoff(proc, stderr_path)
        finally:
            if proc.returncode is None:
                proc.send_signal(signal.SIGINT)
                try:
                    async with asyncio.timeout(15.0):
                        await proc.communicate()
                except TimeoutError:
                    proc.kill()
                    await proc.wait()


async def start_team(
    stack: contextlib.AsyncExitStack, common: list[str], tmp_path: Path, vehicles: int = 3
) -> tuple[Standoff, list[Standoff]]:
    """Agents first (each listens on its vehicle's port), then the ground with the simulator;
    returns once every vehicle is under offboard control."""
    agents = [
        await stack.enter_async_context(
            standoff("agent", "--vehicle", str(i + 1), *common, stderr_path=tmp_path / f"a{i}.err")
        )
        for i in range(vehicles)
    ]
    for i, agent in enumerate(agents):
        await agent.wait_for(f"waiting for vehicle {i + 1}", 60.0)
    ground = await stack.enter_async_context(
        standoff("ground", *common, "--sitl", "--quiet", stderr_path=tmp_path / "g.err")
    )
    await ground.wait_for("ground station ready", 60.0)
    for i, agent in enumerate(agents):
        await agent.wait_for(f"vehicle {i + 1} under offboard control", 60.0)
    return ground, agents


@dataclass(frozen=True)
class TrackRow:
    """One vehicle at one ground tick of ``track.csv``, with the errors the test needs."""

    t_s: float
    vehicle: int
    active: bool
    target_north_m: float
    distance_m: float  # from the true target
    bearing_rad: float  # of the vehicle seen from the true target, from east
    estimate_error_m: float  # the fused estimate from the true target

    @classmethod
    def parse(cls, row: dict[str, str]) -> "TrackRow":
        target = float(row["target_east_m"]), float(row["target_north_m"])
        here = float(row["east_m"]), float(row["north_m"])
        estimate = float(row["estimate_east_m"]), float(row["estimate_north_m"])
        return cls(
            t_s=float(row["t_s"]),
            vehicle=int(row["vehicle"]) - 1,  # track.csv numbers them from 1, as users do
            active=float(row["active"]) > 0.5,
            target_north_m=target[1],
            distance_m=math.dist(here, target),
            bearing_rad=math.atan2(here[1] - target[1], here[0] - target[0]),
            estimate_error_m=math.dist(estimate, target),
        )


def track_rows(path: Path) -> list[TrackRow]:
    with path.open(newline="", encoding="utf-8") as f:
        return [TrackRow.parse(row) for row in csv.DictReader(f)]


def turned_rad(rows: list[TrackRow]) -> float:
    """How far a vehicle went round the target over ``rows`` (its own, in time order)."""
    return sum(
        math.remainder(b.bearing_rad - a.bearing_rad, math.tau) for a, b in itertools.pairwise(rows)
    )


def read_events(path: Path) -> list[dict[str, Any]]:
    """The events of a process's log so far (it flushes whole lines; a torn last one is left)."""
    events = []
    for line in path.read_text(encoding="utf-8").splitlines() if path.exists() else []:
        with contextlib.suppress(json.JSONDecodeError):
            events.append(json.loads(line))
    return events


async def wait_for_event(path: Path, timeout_s: float, **fields: object) -> dict[str, Any]:
    """The first event with these fields in a running process's event log (polled)."""
    async with asyncio.timeout(timeout_s):
        while True:
            for event in read_events(path):
                if fields.items() <= event.items():
                    return event
            await asyncio.sleep(0.1)  # a file another process appends to: no event to await


@contextlib.contextmanager
def running_broker(workdir: Path) -> Iterator[Mosquitto]:
    """mosquitto on the shipped configuration (configs/mosquitto/: logins only, each client
    publishing on its own topics alone); ``login_options`` log a process in."""
    broker = Mosquitto(workdir, team=3)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


def login_options(broker: Mosquitto) -> list[str]:
    """Each process logs in as its identity, its password from the file ``standoff broker``
    wrote for it, and seals every message with the team's key."""
    assert broker.team is not None
    secrets = broker.team.directory / "secrets"
    return [
        "--password-file",
        str(secrets / "{client}.password"),
        "--mission-key-file",
        str(broker.team.mission_key),
    ]


# --- three agents, the broker restarted mid-track ------------------------------------------------


@dataclass
class TeamRun:
    """The processes of the team run, all exited, and its run folder."""

    out: Path
    ground: Standoff
    agents: list[Standoff]
    codes: list[int]
    forged: int = 0  # messages an intruder logged in as agent-2 tried to publish
    forged_denied: int = 0  # of which the broker refused


EYE = tuple(tuple(float(i == j) for j in range(6)) for i in range(6))


async def forge_as_agent_1(broker: Mosquitto, rounds: int = 5) -> tuple[int, int]:
    """A second client logged in as agent-2, holding the team's key (an insider), tries to take
    the mission over at 5 rounds a second: shutdown and hold on ``command/all`` claiming to be
    the ground, vehicle 0's status 10,000 s ahead, the fused estimate 500 m off, the mission
    back to standby. QoS 1, so that the broker says what it did; returns (sent, refused)."""
    assert broker.team is not None
    forgeries: list[tuple[topics.Topic, bus.Message]] = [
        (topics.command(), bus.Command(sender="ground", t_s=50.0, command="shutdown")),
        (topics.command(), bus.Command(sender="ground", t_s=50.0, command="hold")),
        (
            topics.status(0),
            bus.VehicleStatus(
                sender="agent-1",
                t_s=10_000.0,
                vehicle=0,
                east_m=0.0,
                north_m=0.0,
                alt_m=100.0,
                course_rad=0.0,
                speed_m_s=14.0,
                phase_rad=0.0,
                stage="track",
                link="ok",
                healthy=True,
            ),
        ),
        (
            topics.GLOBAL_ESTIMATE,
            bus.GlobalEstimate(sender="ground", t_s=50.0, x=(500.0,) * 6, P=EYE, beta={}),
        ),
        (
            topics.MISSION,
            bus.MissionState(
                sender="ground", t_s=50.0, stage="standby", active=(0,), spacing_rad=math.tau
            ),
        ),
    ]
    key = MissionKey.load(broker.team.mission_key)
    async with open_bus(
        broker.url, client_id="intruder", login=broker.login("agent-2"), mission_key=key
    ) as intruder:
        assert isinstance(intruder, MqttBus)
        intruder.identity = None  # no check of its own: it publishes what it likes
        for _ in range(rounds):
            for topic, message in forgeries:
                await intruder.publish(topic, message, qos=1)
            await asyncio.sleep(0.2)  # the attack's rate is the test's input
        return rounds * len(forgeries), intruder.stats.denied


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def team_run(tmp_path_factory: pytest.TempPathFactory) -> TeamRun:
    tmp_path = tmp_path_factory.mktemp("team")
    mission = write_mission(
        tmp_path,
        end_s=TEAM_END_S,
        standby_east_m=TEAM_STANDBY_EAST_M,
        wait_s=TEAM_WAIT_S,
        leg_north_m=TEAM_LEG_NORTH_M,
    )
    base_port = find_free_udp_base_port(3)
    out = tmp_path / "run"
    with running_broker(tmp_path) as mosquitto:
        common = [str(mission), "--broker", mosquitto.url, "--base-port", str(base_port)]
        common += ["--out", str(out), *login_options(mosquitto)]
        async with contextlib.AsyncExitStack() as stack:
            ground, agents = await start_team(stack, common, tmp_path)
            # mid-mission: every agent has heard that the team tracks the target (an agent cut
            # off before it heard a stage change flies the old stage meanwhile)
            for i in range(3):
                await wait_for_event(
                    out / f"events-agent-{i + 1}.jsonl", 90.0, kind="agent_stage", stage="track"
                )
            forged, forged_denied = await forge_as_agent_1(mosquitto)
            await asyncio.to_thread(mosquitto.stop)
            await asyncio.sleep(OUTAGE_S)  # the outage itself: its length is the test's input
            await asyncio.to_thread(mosquitto.start, keep_port=True)
            assert await ground.finish(120.0) == 0, ground.transcript()
            codes = [await agent.finish(30.0) for agent in agents]
    return TeamRun(out, ground, agents, codes, forged, forged_denied)


def test_ground_and_three_agents_fly_the_mission_over_mosquitto(team_run: TeamRun) -> None:
    out = team_run.out
    # the intruder logged in as agent-2: the broker refused every one of its forgeries
    assert team_run.forged == team_run.forged_denied == 25
    for i, (agent, code) in enumerate(zip(team_run.agents, team_run.codes, strict=True)):
        assert code == 0, agent.transcript()
        assert f"agent {i + 1}: shutdown by the ground station" in agent.stdout()
        assert "hold on exit failed" not in agent.stderr(), agent.transcript()
        report = json.loads((out / f"agent-{i + 1}.json").read_text())
        assert report["reason"] == "shutdown"
        assert report["counters"]["agent"]["ticks"] > 100
        # the agent process's own CPU, measured up to when it wrote its file
        assert report["counters"]["agent"]["cpu_s"] > 0.0
        assert 0.0 < report["counters"]["agent"]["cpu_share_at_1x"] < 0.5
        assert report["counters"]["link"]["setpoints"] > 100
        assert report["counters"]["bus"]["malformed"] == 0
        # through the logins, the ACL and the seals: nothing of the team's own was refused,
        # denied or taken for a forgery
        assert report["counters"]["bus"]["refused"] == 0
        assert report["counters"]["bus"]["denied"] == 0
        assert (out / f"vehicle-{i + 1}.tlog").stat().st_size > 10_000
        agent_events = [json.loads(line) for line in (out / f"events-agent-{i + 1}.jsonl").open()]
        kinds = [e["kind"] for e in agent_events]
        assert "offboard" in kinds
        # events number vehicles from 1
        assert {"kind": "agent_stop", "vehicle": i + 1, "reason": "shutdown"}.items() <= (
            agent_events[-1].items()
        )
        # the ground's own shutdown at the end, not the intruder's in mid-track
        assert agent_events[-1]["t_s"] >= TEAM_END_S - 5.0
        assert "hold" not in [e.get("command") for e in agent_events]

    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is False
    assert summary["mission_t_s"] >= TEAM_END_S
    # the agents' own blocks (their agent-N.json) merged into the ground's summary, from 1
    assert set(summary["links"]) == set(summary["agents"]) == {"1", "2", "3"}
    assert all(summary["links"][str(i + 1)]["setpoints"] > 100 for i in range(3))
    assert all(summary["agents"][str(i + 1)]["ticks"] > 100 for i in range(3))
    assert summary["run"]["process"] == "ground"
    assert summary["convergence"]["time_to_circle_s"] is not None
    assert "track:A-B" in summary["parts"]
    assert (out / "track.csv").stat().st_size > 0
    events = [json.loads(line) for line in (out / "events.jsonl").open()]
    shutdown = next(e for e in events if e["kind"] == "shutdown_sent")
    assert shutdown["t_s"] >= TEAM_END_S
    offline = {e["vehicle"]: e["reason"] for e in events if e["kind"] == "agent_offline"}
    assert offline == {1: "shutdown", 2: "shutdown", 3: "shutdown"}
    assert not any(e["kind"] == "agents_still_online" for e in events)


def test_a_broker_restart_mid_mission_is_survived(team_run: TeamRun) -> None:
    out = team_run.out
    # every process lost the broker once and came back
    back_t = 0.0  # mission time by which every agent was back on the bus
    for i, (agent, code) in enumerate(zip(team_run.agents, team_run.codes, strict=True)):
        assert code == 0, agent.transcript()
        assert f"agent {i + 1}: shutdown by the ground station; vehicle {i + 1} in hold" in (
            agent.stdout()
        )
        report = json.loads((out / f"agent-{i + 1}.json").read_text())
        assert (report["reason"], report["held"]) == ("shutdown", True)
        assert report["counters"]["bus"]["reconnects"] == 1
        # it kept flying through the outage: its statuses were dropped, not waited for, and
        # the vehicle never fell back on its offboard failsafe
        assert report["counters"]["bus"]["unsent"] > 0
        assert report["counters"]["agent"]["offboard_restarts"] == 0
        assert report["counters"]["link"]["left_offboard"] == 0
        agent_events = read_events(out / f"events-agent-{i + 1}.jsonl")
        kinds = [e["kind"] for e in agent_events]
        assert kinds.count("bus_lost") == kinds.count("bus_reconnected") == 1
        back_t = max(back_t, next(e for e in agent_events if e["kind"] == "bus_reconnected")["t_s"])
    events = read_events(out / "events.jsonl")
    kinds = [e["kind"] for e in events]
    assert kinds.count("bus_lost") == kinds.count("bus_reconnected") == 1
    # a broker going down may publish the agents' wills ("vanished"); their births, on the
    # reconnection, said "online" again: the ground still knew every agent at the end
    for i in range(3):
        said = [
            (e["kind"], e["reason"])
            for e in events
            if e["kind"] in ("agent_online", "agent_offline") and e["vehicle"] == i + 1
        ]
        assert said[0][0] == "agent_online", said
        assert said[-1] == ("agent_offline", "shutdown"), said
        for (kind, reason), (then, _) in itertools.pairwise(said):
            assert kind == "agent_online" or (reason == "vanished" and then == "agent_online")
    shutdown = next(e for e in events if e["kind"] == "shutdown_sent")
    assert shutdown["agents"] == [1, 2, 3]
    assert not any(e["kind"] == "agents_still_online" for e in events)

    # after the restart the estimate follows the moving target and the team orbits it
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is False
    assert summary["mission_t_s"] >= TEAM_END_S
    # the agents' own blocks (their agent-N.json) merged into the ground's summary, from 1
    assert set(summary["links"]) == set(summary["agents"]) == {"1", "2", "3"}
    assert all(summary["links"][str(i + 1)]["setpoints"] > 100 for i in range(3))
    assert all(summary["agents"][str(i + 1)]["ticks"] > 100 for i in range(3))
    assert summary["run"]["process"] == "ground"
    assert "track:A-B" in summary["parts"]
    # From 2 s of mission time after the reconnection (the ground's first tick still has its
    # pre-outage estimate, some 20 m behind the target that moved meanwhile): the estimate stays
    # on the target as it drives on (a frozen one falls behind by 3 m/s; 2-9 m seen), and each
    # vehicle goes on circling the true target. The distance bound is loose on purpose: the
    # track stage's guidance alone has shown excursions of up to ~115 m from the circle in this
    # test's mission without any outage; agents cut off from the ground ran 250-335 m away.
    rows = track_rows(out / "track.csv")
    after = [r for r in rows if back_t + 2.0 < r.t_s < TEAM_END_S and r.active]
    assert after[-1].target_north_m - after[0].target_north_m > 30.0
    assert max(r.estimate_error_m for r in after) < 15.0
    for i in range(3):
        mine = [r for r in after if r.vehicle == i]
        assert len(mine) > 100, f"vehicle {i}: {len(mine)} ticks heard after the restart"
        assert abs(turned_rad(mine)) > math.pi / 2, f"vehicle {i} did not circle the target"
        assert max(abs(r.distance_m - 90.0) for r in mine) < 150.0, f"vehicle {i}"


def test_the_processes_recordings_replay_to_the_ground_s_figures(
    team_run: TeamRun, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each process recorded what it was fed, in its own file; put together in the run folder
    they replay (standoff replay) to the ground's stages and figures, the outage included."""
    names = sorted(p.name for p in team_run.out.glob("observations*.jsonl"))
    assert names == [f"observations-agent-{i + 1}.jsonl" for i in range(3)] + [
        "observations-ground.jsonl"
    ]
    assert main(["replay", str(team_run.out)]) == 0
    out = capsys.readouterr().out
    assert "stages the same, figures the same" in out, out
    assert "were not produced" not in out, out


# --- a team of two: SIGTERM to agent 0, then Ctrl-C on the ground --------------------------------


@dataclass
class SignalledRun:
    """A team of two flying a long mission: agent 0 stopped by SIGTERM (and its vehicle heard in
    hold on the port the agent left), then the ground station by SIGINT with agent 1 flying."""

    out: Path
    ground: Standoff
    ground_code: int
    agent: Standoff  # agent 0
    agent_code: int
    hold_beat: Any  # vehicle 1's first autopilot HEARTBEAT after agent 0 exited
    other: Standoff  # agent 1, told to shut down by the ground
    other_code: int


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def signalled_run(tmp_path_factory: pytest.TempPathFactory) -> SignalledRun:
    tmp_path = tmp_path_factory.mktemp("signalled")
    mission = write_mission(tmp_path, vehicles=2, end_s=600.0)
    base_port = find_free_udp_base_port(2)
    out = tmp_path / "run"
    with running_broker(tmp_path) as mosquitto:
        common = [str(mission), "--broker", mosquitto.url, "--base-port", str(base_port)]
        common += ["--out", str(out), *login_options(mosquitto)]
        async with contextlib.AsyncExitStack() as stack:
            ground = await stack.enter_async_context(
                standoff("ground", *common, "--sitl", "--quiet", stderr_path=tmp_path / "g.err")
            )
            await ground.wait_for("ground station ready", 60.0)
            agent, other = [
                await stack.enter_async_context(
                    standoff(
                        "agent",
                        "--vehicle",
                        str(i + 1),
                        *common,
                        stderr_path=tmp_path / f"a{i}.err",
                    )
                )
                for i in range(2)
            ]
            await agent.wait_for("vehicle 1 under offboard control", 60.0)
            await other.wait_for("vehicle 2 under offboard control", 60.0)
            agent.proc.send_signal(signal.SIGTERM)
            agent_code = await agent.finish(STOP_S)
            # the vehicle itself, heard on the port its agent has left
            async with RawClient(base_port) as vehicle:
                beat = await vehicle.wait_for(
                    lambda m: (
                        m.get_type() == "HEARTBEAT" and m.get_srcComponent() == AUTOPILOT_COMPONENT
                    ),
                    timeout_s=10.0,
                )
            ground.proc.send_signal(signal.SIGINT)
            ground_code = await ground.finish(60.0)
            other_code = await other.finish(30.0)
    return SignalledRun(out, ground, ground_code, agent, agent_code, beat, other, other_code)


def test_sigterm_to_a_flying_agent_holds_its_vehicle_and_exits_143(
    signalled_run: SignalledRun,
) -> None:
    run, out = signalled_run, signalled_run.out
    agent = run.agent
    assert run.agent_code == 128 + signal.SIGTERM, agent.transcript()
    assert run.hold_beat.custom_mode == HOLD.custom_mode, run.hold_beat
    assert run.ground_code == 130, run.ground.transcript()

    assert "agent 1: stopped by SIGTERM; vehicle 1 in hold" in agent.stdout()
    # the agent's hold, not the vehicle's offboard failsafe (which would go to hold too)
    assert "left OFFBOARD on its own" not in agent.stderr(), agent.transcript()
    assert "hold on exit failed" not in agent.stderr(), agent.transcript()
    report = json.loads((out / "agent-1.json").read_text())
    assert (report["reason"], report["stopped_by"], report["held"]) == ("SIGTERM", 15, True)
    agent_events = [json.loads(line) for line in (out / "events-agent-1.jsonl").open()]
    assert {"kind": "hold", "vehicle": 1, "reason": "SIGTERM"}.items() <= next(
        e for e in agent_events if e["kind"].startswith("hold")
    ).items()
    assert {"kind": "agent_stop", "reason": "SIGTERM", "held": True}.items() <= (
        agent_events[-1].items()
    )
    # it said it was going offline (the ground heard that, not the broker's last will)
    events = [json.loads(line) for line in (out / "events.jsonl").open()]
    offline = [(e["vehicle"], e["reason"]) for e in events if e["kind"] == "agent_offline"]
    assert [(v, reason) for v, reason in offline if v == 1] == [(1, "SIGTERM")]


def test_ctrl_c_on_the_ground_station_interrupts_and_tells_the_agents(
    signalled_run: SignalledRun,
) -> None:
    # Ctrl-C on the ground station: the run folder says interrupted and the agents are told to
    # shut down.
    run, out = signalled_run, signalled_run.out
    assert run.ground_code == 130, run.ground.transcript()
    events = [json.loads(line) for line in (out / "events.jsonl").open()]
    kinds = [e["kind"] for e in events]
    assert "interrupted" in kinds
    assert "shutdown_sent" in kinds
    assert json.loads((out / "summary.json").read_text())["interrupted"] is True
    # the agent still flying heard it, and left: agent 0 had gone on its SIGTERM before
    assert run.other_code == 0, run.other.transcript()
    offline = [(e["vehicle"], e["reason"]) for e in events if e["kind"] == "agent_offline"]
    assert offline == [(1, "SIGTERM"), (2, "shutdown")]


# --- commands that refuse to start -------------------------------------------------------------


async def test_agent_with_the_broker_down_exits_with_one_line(tmp_path: Path) -> None:
    mission = write_mission(tmp_path)
    with refused_port() as port:
        async with standoff(
            "agent", "--vehicle", "1", str(mission), "--broker", f"mqtt://127.0.0.1:{port}",
            "--out", str(tmp_path / "run"), stderr_path=tmp_path / "a.err",
        ) as agent:  # fmt: skip
            assert await agent.finish(40.0) == 2
    # the bus logs each refused attempt (warnings), then the command gives its one-line reason
    *retries, line = agent.stderr().strip().splitlines()
    assert line.startswith("standoff agent: error: cannot connect to the broker at ")
    assert f"127.0.0.1:{port}" in line
    assert all(" WARNING app.adapters.bus.mqtt: " in r for r in retries), agent.stderr()
    assert not (tmp_path / "run" / "vehicle-1.tlog").exists()


def exit_code_of(argv: list[str]) -> int:
    """``python -m app ARGV`` in this process: ``main``'s exit code (argparse's included), with
    the root logger as a fresh process has it (no handlers: ``main``'s ``basicConfig`` sends
    any log line to stderr, captured), restored after. A bad input is refused before any I/O,
    so the commands below need no process of their own (and no 1-3 s of imports each)."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    root.handlers.clear()
    try:
        return main(argv)
    except SystemExit as exc:  # argparse's exit: the code the interpreter would exit with
        code = exc.code
        return code if isinstance(code, int) else int(code is not None)
    finally:
        for handler in root.handlers:
            if handler not in handlers:
                handler.close()
        root.handlers[:] = handlers
        root.setLevel(level)


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        (["--broker", "http://127.0.0.1:1883"], "bad broker URL"),
        (  # numbered from 1, as the system id: a team of 3 is 1..3
            ["--broker", "mqtt://127.0.0.1:1883", "--vehicle", "4"],
            "standoff agent: error: --vehicle 4: the mission's vehicles are 1..3",
        ),
        (
            ["--broker", "mqtt://127.0.0.1:1883", "--vehicle", "0"],
            "standoff agent: error: --vehicle 0: the mission's vehicles are 1..3",
        ),
        (["--broker", "mqtt://127.0.0.1:1883", "--connect", "udp://x"], "vehicle URL 'udp://x'"),
        ([], "no MQTT broker"),
    ],
)
def test_agent_bad_input_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], reason: str
) -> None:
    mission = write_mission(tmp_path)
    argv = ["agent", str(mission), *(args if "--vehicle" in args else ["--vehicle", "1", *args])]
    assert exit_code_of(argv) == 2
    assert reason in one_line(capsys.readouterr().err)


def test_ground_bad_broker_url_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission = write_mission(tmp_path)
    argv = ["ground", str(mission), "--broker", "mqtt://127.0.0.1:1883/path", "--quiet"]
    assert exit_code_of(argv) == 2
    assert one_line(capsys.readouterr().err).startswith("standoff ground: error: bad broker URL")
