"""An agent's teammates' statuses: heard one step each against a control tick's in one step.

Run:  .venv/bin/python -m benchmarks.bench_team_status [--teams 3 10 20] [--ticks N]

Every agent hears every teammate's status (10 Hz each), so over a team of n the process hears
n (n - 1) statuses per status period. The agent loop takes those that came since its last
control tick in one ``HeardTeammates`` step; this times that against one step per status (as
the loop did before), with the loop's CPU clock around each step, on the same state and fixes,
side by side and alternating, the better of three each. Prints microseconds per agent and tick
and the ratio.
"""

import argparse
import math
import time
from dataclasses import replace

from app.config import load_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan
from app.core.mission import agent as logic


def _time(
    state: logic.MissionAgentState,
    batches: list[tuple[tuple[int, logic.TeammateFix], ...]],
    params: logic.MissionAgentParams,
    ticks: int,
) -> float:
    """Seconds per tick to step ``batches`` (each one step), timed as the loop times a step."""
    started = time.perf_counter()
    cpu = 0.0
    for _ in range(ticks):
        s = state
        for batch in batches:
            t0 = time.thread_time()
            s, _ = logic.step(s, logic.HeardTeammates(batch), params)
            cpu += time.thread_time() - t0
    return (time.perf_counter() - started) / ticks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teams", type=int, nargs="+", default=[3, 10, 20])
    parser.add_argument("--ticks", type=int, default=2000)
    args = parser.parse_args()
    plan = build_plan(load_config("hil", MissionConfig))
    params = plan.agents[0]
    print("team  statuses/tick  one step each (us)  one step a tick (us)  ratio")
    for n in args.teams:
        state = logic.hear_mission(
            logic.initial_agent_state(params, 0.2, 0.1), "track", tuple(range(n))
        )
        state = replace(state, now_t_s=100.0)
        fixes = tuple(
            (j, logic.TeammateFix(99.9, 30.0 * j, 5.0, 0.1 * j, 14.0)) for j in range(1, n)
        )
        each, once = math.inf, math.inf
        for _ in range(3):
            each = min(each, _time(state, [(f,) for f in fixes], params, args.ticks))
            once = min(once, _time(state, [fixes], params, args.ticks))
        print(f"{n:4d}  {n - 1:13d}  {each * 1e6:18.1f}  {once * 1e6:20.1f}  {once / each:5.2f}x")


if __name__ == "__main__":
    main()
