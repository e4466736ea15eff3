"""Injected faults over real UDP: a vehicle's link cut and restored, a camera stopped."""

import asyncio

from pymavlink.dialects.v20 import common as mavlink

from sitl.px4 import HOLD
from tests.support.sitl_fixtures import RawClient, running_sim, sim_config, stream_setpoints


async def test_cut_link_goes_silent_triggers_the_failsafe_and_comes_back():
    config = sim_config(2, speedup=5.0, takeoff="launch")
    async with running_sim(config) as sim:
        clients = [RawClient(e.gcs_port) for e in sim.endpoints]
        for client in clients:
            await client.__aenter__()
        stop = asyncio.Event()
        try:
            async with asyncio.TaskGroup() as group:
                for sysid, client in enumerate(clients, start=1):
                    await client.heartbeat()
                    assert (
                        await client.command(
                            mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=sysid
                        )
                        == 0
                    )
                    group.create_task(
                        stream_setpoints(client, sysid, 18.0, 0.0, 20.0, stop), name=f"sp{sysid}"
                    )
                await asyncio.sleep(0.1)
                for sysid, client in enumerate(clients, start=1):
                    assert (
                        await client.command(
                            mavlink.MAV_CMD_DO_SET_MODE, 1.0, 6.0, 0.0, target_system=sysid
                        )
                        == 0
                    )

                sim.set_link(0, up=False)
                await sim.wait_until(sim.time_s + 0.5)  # what was in flight has landed
                cut = len(clients[0].inbox.messages)
                truth = await sim.wait_until(sim.time_s + 3.0)
                # vehicle 1 heard nothing and said nothing; vehicle 2 flew on in offboard
                assert truth.vehicles[0].mode == HOLD.name
                assert not truth.vehicles[0].link_up
                assert truth.vehicles[1].mode == "offboard"
                assert len(clients[0].inbox.messages) == cut
                assert sim.stats[0].dropped_link_down > 0

                sim.set_link(0, up=True)
                beat = await clients[0].wait_for(
                    lambda m: m.get_type() == "HEARTBEAT", timeout_s=2.0
                )
                assert beat.custom_mode == HOLD.custom_mode
                await asyncio.sleep(0.2)  # setpoints flow again before offboard is asked for
                assert (
                    await clients[0].command(
                        mavlink.MAV_CMD_DO_SET_MODE, 1.0, 6.0, 0.0, target_system=1
                    )
                    == 0
                )
                assert sim.truth().vehicles[0].mode == "offboard"
                stop.set()
        finally:
            for client in clients:
                await client.__aexit__()


async def test_stopped_camera_sends_nothing_and_restarts():
    config = sim_config(1, speedup=10.0, takeoff="launch")
    async with running_sim(config) as sim, RawClient(sim.endpoints[0].gcs_port) as client:
        await client.heartbeat()
        assert await client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target_system=1) == 0

        def is_fix(m):
            return m.get_type() == "CAMERA_TRACKING_GEO_STATUS"

        fix = await client.wait_for(is_fix, timeout_s=2.0)
        assert fix.get_srcComponent() == 100
        assert fix.tracking_status == mavlink.CAMERA_TRACKING_STATUS_FLAGS_ACTIVE
        sim.set_camera(0, enabled=False)
        await sim.wait_until(sim.time_s + 0.2)
        mark = len(client.inbox.messages)
        await sim.wait_until(sim.time_s + 3.0)
        assert not any(is_fix(m) for m in client.inbox.messages[mark:])
        assert any(m.get_type() == "GLOBAL_POSITION_INT" for m in client.inbox.messages[mark:])
        sim.set_camera(0, enabled=True)
        await client.wait_for(is_fix, timeout_s=2.0)


def test_a_failing_vehicle_step_is_logged_and_does_not_stop_the_others(caplog):
    from sitl.config import SimConfig, default_vehicles
    from sitl.server import SimulatorServer

    sim = SimulatorServer(SimConfig(vehicles=default_vehicles(2), takeoff="launch"))
    for vehicle in sim.vehicles:
        vehicle.arm(0.0)

    def broken(*_args):
        raise ZeroDivisionError("a bug")

    sim.vehicles[0].advance = broken  # type: ignore[method-assign]
    before = sim.vehicles[1].state
    truth = sim.run_offline(1.0)
    assert sim.step_errors == 50
    assert truth.vehicles[1].state.north_m > before.north_m + 15.0
    assert "physics step failed" in caplog.text
