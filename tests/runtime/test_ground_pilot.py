"""The ground station and a vehicle its pilot flies: heard (never lost), out of the formation
while the pilot has it, back in once its agent resumes; the live view says so."""

import asyncio
from collections.abc import Callable

from app.adapters.bus import InProcessBroker, InProcessBus
from app.compose.parts import ground_station
from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.mission.stage import Stage
from app.runtime.ports import messages as bus
from app.runtime.ports import topics
from app.runtime.ports.view import MissionSnapshot


class Events:
    def __init__(self) -> None:
        self.seen: list[tuple[str, float, dict[str, object]]] = []

    def emit(self, kind: str, t_s: float, **fields: object) -> None:
        self.seen.append((kind, t_s, fields))

    def kinds(self) -> list[str]:
        return [k for k, _t, _f in self.seen]


async def until(predicate: Callable[[], bool]) -> None:
    async with asyncio.timeout(5.0):
        while not predicate():  # noqa: ASYNC110
            await asyncio.sleep(0.001)


def status(vehicle: int, t_s: float, control: str = "mission") -> bus.VehicleStatus:
    return bus.VehicleStatus(
        sender=f"agent-{vehicle + 1}",
        t_s=t_s,
        vehicle=vehicle,
        east_m=-1000.0 + 150.0 * vehicle,
        north_m=150.0,
        alt_m=100.0,
        course_rad=0.0,
        speed_m_s=14.0,
        phase_rad=0.0,
        stage=Stage.GATHER,
        link="ok",
        healthy=True,
        control=control,
        flight_mode="POSCTL" if control == "pilot" else "OFFBOARD",
    )


async def test_a_vehicle_its_pilot_flies_is_heard_not_lost_and_out_of_the_formation() -> None:
    plan = build_plan(load_config("test-short", MissionConfig))
    broker = InProcessBroker()
    events = Events()
    snapshots: list[MissionSnapshot] = []
    async with (
        InProcessBus(broker, client_id="ground") as ground_bus,
        InProcessBus(broker, client_id="agents") as agents,
        asyncio.TaskGroup() as tg,
    ):
        ground = ground_station(
            plan, ground_bus, events, builtin=True, on_snapshot=snapshots.append
        )
        running = tg.create_task(ground.run())
        await asyncio.sleep(0.01)  # subscribed

        async def second(t0: float, piloted: bool) -> None:
            for k in range(10):
                t = t0 + 0.1 * k
                for v in range(3):
                    control = "pilot" if piloted and v == 1 else "mission"
                    await agents.publish(topics.status(v), status(v, t, control))
                await asyncio.sleep(0.001)

        await second(0.0, piloted=False)
        await until(lambda: ground.state.active == (0, 1, 2))
        await second(1.0, piloted=True)
        for t0 in (2.0, 3.0, 4.0):  # longer than lost_after_s: still heard every tick
            await second(t0, piloted=True)
        await until(lambda: ground.state.active == (0, 2))
        assert "vehicle_with_pilot" in events.kinds()
        report = ground.state.report(1)
        assert report is not None
        assert report.t_s >= 4.8  # heard all along
        assert snapshots[-1].vehicles[1].link == "pilot"
        await second(5.0, piloted=False)
        await until(lambda: ground.state.active == (0, 1, 2))
        assert "vehicle_back_from_pilot" in events.kinds()
        assert [k for k in events.kinds() if k == "vehicle_with_pilot"] == ["vehicle_with_pilot"]
        running.cancel()
