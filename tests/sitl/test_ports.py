"""Free UDP port runs for simulators, away from the ports the kernel hands out itself."""

import random
from pathlib import Path

from sitl.ports import ephemeral_ports, find_free_udp_base_port, pick_range, udp_ports_free


def test_the_ephemeral_range_is_read_from_the_kernel_file(tmp_path: Path) -> None:
    path = tmp_path / "ip_local_port_range"
    path.write_text("32768\t60999\n")
    assert ephemeral_ports(path) == range(32768, 61000)
    path.write_text("garbage")
    assert ephemeral_ports(path) is None
    assert ephemeral_ports(tmp_path / "missing") is None


def test_runs_are_picked_below_the_ephemeral_ports_where_there_is_room() -> None:
    assert pick_range(range(32768, 61000)) == (20000, 32768)
    # too little room below (or unknown): the whole range, as before
    assert pick_range(range(21000, 61000)) == (20000, 60000)
    assert pick_range(None) == (20000, 60000)


def test_a_found_run_is_free_and_clear_of_the_ephemeral_ports() -> None:
    ephemeral = ephemeral_ports()
    for seed in range(20):
        base = find_free_udp_base_port(20, rng=random.Random(seed))
        assert udp_ports_free(base, 20)
        if ephemeral is not None and ephemeral.start - 20000 >= 2000:
            assert base + 20 <= ephemeral.start
