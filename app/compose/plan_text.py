"""The plan of a mission file as text, what ``standoff check`` and ``standoff fly --dry-run``
print: the team with its system ids, altitudes, URLs and ports, the ground-station forward,
the observations, the bus, the stages and their thresholds, the target and end time, and the
parameters each autopilot adapter reads and sets before take-off. Builds nothing, opens
nothing."""

from app.config.plan import MissionPlan
from app.runtime.ports import topics


def _adapter_parameters(name: str, plan: MissionPlan, builtin: bool) -> list[str]:
    """What the adapter ``name`` reads and sets on its autopilot before take-off."""
    from app.adapters.vehicle.autopilots import arduplane, px4
    from app.adapters.vehicle.autopilots.base import MAVSDK_GCS_SYSTEM_ID
    from app.compose.parts import link_config

    link = link_config(plan, builtin)
    lim = plan.config.limits
    speeds = f"{lim.min_speed_m_s:g}..{lim.max_speed_m_s:g} m/s"
    if name == "velocity":
        return ["none: velocity + yaw setpoints, no parameter read or changed"]
    if name == "px4-fixed-wing":
        action = getattr(link, "px4_offboard_loss_action", px4.COM_OBL_RC_ACT_HOLD)
        if action is None:
            return [f"{px4.COM_OBL_RC_ACT} left alone (the vehicle's own offboard-loss action)"]
        return [
            f"{px4.FW_AIRSPD_MIN}..{px4.FW_AIRSPD_MAX} read: must hold {speeds}, else the "
            "vehicle is refused",
            f"{px4.COM_OBL_RC_ACT} set to {action} ({'hold' if action == 5 else 'as configured'}"
            ") where it differs: what PX4 does about 1 s after the setpoints stop",
            f"airspeed in OFFBOARD: {px4.FW_AIRSPD_TRIM} (PX4 v1.16 flies no commanded speed)",
        ]
    if name == "arduplane":
        lines = []
        if getattr(link, "arduplane_airspeed_check", True):
            lines.append(
                f"{arduplane.AIRSPEED_MIN}..{arduplane.AIRSPEED_MAX} (before 4.5: "
                f"{arduplane.ARSPD_FBW_MIN}..{arduplane.ARSPD_FBW_MAX}) read: must hold "
                f"{speeds}, else the vehicle is refused"
            )
        rates = ", ".join(arduplane.TELEMETRY_MESSAGES)
        lines.append(f"{rates} asked at {arduplane.DEFAULT_TELEMETRY_RATE_HZ:g} Hz")
        if getattr(link, "arduplane_gcs_failsafe", True):
            lines += [
                f"{arduplane.SYSID_MYGCS} (4.7: {arduplane.MAV_GCS_SYSID}) set to "
                f"{MAVSDK_GCS_SYSTEM_ID}, this app's system id, unless it already is",
                f"{arduplane.FS_LONG_ACTN} {arduplane.FS_LONG_ACTN_CONTINUE} (continue) set to "
                f"{arduplane.FS_LONG_ACTN_RTL} (RTL)",
                f"{arduplane.FS_GCS_ENABL} 0 or 3 set to {arduplane.FS_GCS_ENABL_HEARTBEAT} "
                f"(heartbeat loss), {arduplane.GCS_HEARTBEAT_WAIT_S:g} s after the GCS id",
            ]
        else:
            lines.append(f"GCS failsafe ({arduplane.FS_GCS_ENABL}) left alone")
        return lines
    return [f"unknown adapter {name!r}"]


def describe_plan(
    plan: MissionPlan,
    connect: tuple[str, ...] | list[str] = (),
    broker: str | None = None,
    base_port: int | None = None,
    source: str = "",
) -> str:
    """The plan as lines for the terminal (``standoff check``, ``standoff fly --dry-run``);
    ``ConfigError`` for a URL or broker that would not do."""
    from app.adapters.bus import BrokerUrl
    from app.adapters.vehicle.mavsdk.urls import validate_url

    cfg = plan.config
    urls = list(connect or cfg.link.connect)
    builtin = not urls
    for url in urls:
        validate_url(url)
    bus = broker if broker is not None else cfg.bus
    if bus is not None:
        BrokerUrl.parse(bus)
    lines = [
        f"{cfg.name}: valid{f' ({source})' if source else ''}",
        f"  {plan.count} vehicles orbiting at r_d = {cfg.radius_m:g} m ({cfg.orbit}), "
        f"mission ends at {plan.end_t_s:.1f} s of mission time",
    ]
    port = base_port if base_port is not None else cfg.sim.base_port
    if builtin:
        s = cfg.sim
        lines.append(
            f"vehicles: the built-in simulator ({s.autopilot} personality, speed-up "
            f"{s.speedup:g}, seed {s.seed}, telemetry {s.telemetry_rate_hz:g} Hz; free ports "
            f"are taken if {port}.. are busy)"
        )
    else:
        lines.append(
            f"vehicles: external, on {', '.join(urls)} (one MAVSDK hub; each vehicle is found "
            "by its system id on any of them)"
        )
    # vehicles as users see them: numbered from 1, as their system ids, their agents' bus
    # logins and what `standoff agent --vehicle N` takes
    lines.append(
        f"  {'vehicle (system id)':>19}  {'agent login':>11}  {'--vehicle':>9}  {'altitude':>8}"
        + ("  URL" if builtin else "")
    )
    for i in range(plan.count):
        url = f"  udpin://127.0.0.1:{port + i}" if builtin else ""
        altitude = cfg.link.vehicle_altitude_m(i)
        login = topics.agent(i)
        lines.append(f"  {i + 1:>19}  {login:>11}  {i + 1:>9}  {altitude:>6g} m{url}")
    gcs = getattr(cfg.link, "gcs_forward", None)
    if gcs is not None:
        lines.append(f"ground station forward: {gcs or 'off'}")
    camera = getattr(cfg.link, "camera_component_id", 100)
    obs = cfg.observations
    where = {
        "camera": f"each vehicle's CAMERA_TRACKING_GEO_STATUS (component {camera})",
        "simulated": f"simulated by the ground: sigma {obs.sigma_m:g} m at {obs.rate_hz:g} Hz",
        "replay": f"replayed from {obs.replay_file}",
        "external": f"published on the bus under {obs.external_topic}",
    }[obs.source]
    lines.append(f"observations: {where}")
    lines.append(f"bus: {bus or 'in-process'}")
    st = cfg.stages
    lines += [
        "stages:",
        f"  standby  until {cfg.tracking_command_s:g} s: loiter r = {cfg.standby.radius_m:g} m "
        f"about ({cfg.standby.east_m:g}, {cfg.standby.north_m:g}) m east, north",
        "  gather   to the circle, phase keeping on",
        f"  adjust   once every vehicle is within {st.arrive_tolerance_m:g} m of the circle",
        f"  track    once formed (within {st.radius_tolerance_m:g} m and "
        f"{st.spacing_tolerance_deg:g} deg) for {st.dwell_s:g} s, or the target moves faster "
        f"than {st.moving_speed_m_s:g} m/s",
        f"target: {cfg.target.kind}, {plan.target.duration_s:.1f} s scripted"
        + (f", then {cfg.tail_s:g} s of tail" if cfg.end_s is None else ""),
    ]
    if builtin:
        adapters = [cfg.link.autopilot if cfg.link.autopilot != "auto" else "velocity"]
    elif cfg.link.autopilot != "auto":
        adapters = [cfg.link.autopilot]
    else:
        adapters = ["px4-fixed-wing", "arduplane"]
    lines.append(
        "autopilot parameters, before take-off"
        + (" (the adapter is chosen from what each vehicle reports):" if len(adapters) > 1 else ":")
    )
    for name in adapters:
        lines.append(f"  {name}:")
        lines += [f"    {line}" for line in _adapter_parameters(name, plan, builtin)]
    if any(name != "velocity" for name in adapters):
        lines.append("  every parameter changed is written back at the end")
    return "\n".join(lines)
