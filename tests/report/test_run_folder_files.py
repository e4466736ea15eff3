"""The run folder's files read back: observations.jsonl (what replay is fed), config.json,
track.csv as samples; and the phase figure's wrapping."""

import json
import math
from pathlib import Path

import pytest

from app.adapters.observations_log import ObservationLog
from app.cli import main
from app.config import load_config
from app.config.mission import MissionConfig
from app.core.estimation.messages import Observation
from app.core.mission.ground import VehicleReport
from app.core.mission.team import TeamSample, VehicleSample
from app.errors import InputError
from app.report.mission_plots import broken_at_wraps, spacing_error_deg
from app.report.replay import read_recording
from app.report.run_folder import (
    read_run_config,
    read_track_samples,
    write_run_config,
    write_run_folder,
)


def test_observations_round_trip_exactly(tmp_path: Path) -> None:
    path = tmp_path / "observations.jsonl"
    obs = Observation(12.345678901234567, "1", 0.1 + 0.2, -1e-17, None)
    report = VehicleReport(3.3, 1.0 / 3.0, 2.0, 0.7, 14.000000000000002, link_ok=False)
    with ObservationLog(path, 2, truth=True) as log:
        log.observation(1, obs, -math.inf)
        log.status(0, report, 3.25)
        log.local(1, 12.4, None)
        log.fused(0, 12.6, 12.5)
    recording = read_recording(path)
    assert recording.vehicles == 2
    assert recording.truth
    kinds = [r["kind"] for r in recording.records]
    assert kinds == ["observation", "status", "local", "fused"]
    first, status = recording.records[0], recording.records[1]
    assert first["t_s"] == obs.t_s
    assert first["east_m"] == 0.1 + 0.2
    assert first["sigma_m"] is None
    assert status["north_m"] == 2.0
    assert status["east_m"] == 1.0 / 3.0
    assert status["clock_t_s"] == 3.25
    assert recording.records[2]["clock_t_s"] is None
    assert recording.records[0]["clock_t_s"] is None  # -inf: no clock yet
    assert recording.records[3]["clock_t_s"] == 12.5
    assert status["link_ok"] is False
    assert status["healthy"] is True


def test_a_recording_cut_short_is_read_up_to_its_last_whole_line(tmp_path: Path) -> None:
    path = tmp_path / "observations.jsonl"
    with ObservationLog(path, 1, truth=False) as log:
        log.fused(0, 1.0, 0.9)
    path.write_text(path.read_text() + '{"kind": "loc')
    assert len(read_recording(path).records) == 1


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ('{"kind": "status", "vehicle": 3, "t_s": 1.0}', "'vehicle' must be 0..1"),
        ('{"kind": "teleport", "vehicle": 0, "t_s": 1.0}', "unknown kind"),
        ('{"kind": "fused", "vehicle": 0, "t_s": "soon"}', "'t_s' is not a number"),
        ("[1, 2]", "not a JSON object"),
    ],
)
def test_a_bad_record_names_its_line(tmp_path: Path, line: str, reason: str) -> None:
    path = tmp_path / "observations.jsonl"
    header = {"kind": "header", "schema": 1, "vehicles": 2, "truth": True}
    path.write_text(json.dumps(header) + "\n" + line + "\n" + line + "\n")
    with pytest.raises(InputError, match=f"observations.jsonl:2: .*{reason}"):
        read_recording(path)


def test_no_recording_says_so(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_recording(tmp_path / "observations.jsonl")


def test_config_json_holds_the_mission_and_its_estimator(tmp_path: Path) -> None:
    config = load_config("test-short", MissionConfig)
    write_run_config(tmp_path, config)
    mission, estimator = read_run_config(tmp_path)
    assert mission == config
    assert len(estimator.imm.models) >= 2


def test_a_folder_without_config_json_reads_the_summary_s_run_block(tmp_path: Path) -> None:
    config = load_config("test-short", MissionConfig)
    summary = {"run": {"config": config.model_dump(mode="json")}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    mission, estimator = read_run_config(tmp_path)
    assert mission == config
    assert estimator.imm.models


def _sample(t: float, stage: str, angles_deg: tuple[float, ...]) -> TeamSample:
    vehicles = tuple(
        VehicleSample(
            i, True, 90.0 * math.cos(math.radians(a)), 90.0 * math.sin(math.radians(a)), 14.0
        )
        for i, a in enumerate(angles_deg)
    )
    return TeamSample(t, stage, "A-B", 0.0, 0.0, 0.0, 0.0, (0.5, -0.5, 0.0, 0.0), vehicles)


def test_the_spacing_error_is_drawn_in_minus_180_to_180() -> None:
    # vehicles 0 and 1 together, 2 opposite: gaps 0, 180, 180 -> errors -120, 60, 60
    errors = spacing_error_deg(_sample(0.0, "gather", (10.0, 10.0001, 190.0)))
    assert all(-180.0 < e <= 180.0 for e in errors.values())
    assert sorted(round(e) for e in errors.values()) == [-120, 60, 60]
    # 0 passes the others: its gap goes from 359 to 1 degree, a raw jump of 358
    before = spacing_error_deg(_sample(0.0, "gather", (0.0, 1.0, 2.0)))
    after = spacing_error_deg(_sample(0.1, "gather", (3.0, 1.0, 2.0)))
    assert all(abs(after[k] - before[k]) < 180.0 for k in (1, 2))


def test_a_series_that_still_wraps_is_broken_not_joined() -> None:
    ts, values = broken_at_wraps([(0.0, 170.0), (1.0, 179.0), (2.0, -179.0), (3.0, -170.0)])
    assert ts[:2] == [0.0, 1.0]
    assert math.isnan(ts[2])
    assert math.isnan(values[2])
    assert values[3:] == [-179.0, -170.0]


@pytest.mark.slow  # matplotlib draws three figures: about 2 s
def test_plot_redraws_a_run_folder_from_its_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    samples = [_sample(0.5 * k, "gather", (5.0 * k, 100.0, 200.0)) for k in range(20)]
    samples += [
        _sample(0.5 * k, "track", (5.0 * k, 125.0 + 5 * k, 245.0 + 5 * k)) for k in range(20, 40)
    ]
    config = load_config("test-short", MissionConfig)
    run = tmp_path / "run-1"
    run.mkdir()
    write_run_config(run, config)
    write_run_folder(
        run,
        samples,
        radius_m=90.0,
        tracking_command_s=5.0,
        radius_tolerance_m=3.0,
        spacing_tolerance_rad=math.radians(2.0),
        extra={"mission": config.name},
    )
    back = read_track_samples(run / "track.csv")
    assert [s.t_s for s in back] == [s.t_s for s in samples]
    assert back[-1].stage == "track"
    assert back[-1].target_segment == "A-B"
    assert back[3].estimate == (0.5, -0.5, 0.0, 0.0)
    assert back[3].vehicles[0].east_m == pytest.approx(samples[3].vehicles[0].east_m, abs=1e-4)
    for png in run.glob("*.png"):
        png.unlink()
    assert main(["plot", str(run)]) == 0
    assert sorted(p.name for p in run.glob("*.png")) == [
        "distance_error.png",
        "estimate_error.png",
        "phase_difference.png",
        "trajectories.png",
    ]
    assert "phase_difference.png" in capsys.readouterr().out


def test_plot_refuses_what_is_not_a_run_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["plot", str(tmp_path)]) == 2
    assert "no config.json" in capsys.readouterr().err
    assert main(["plot", str(tmp_path), "--radius-m", "90"]) == 2
    assert "track.csv: no such file" in capsys.readouterr().err


def test_outages_are_marked_in_the_track_file_with_the_sample_after_their_hole() -> None:
    from app.report.run_folder import outage_marks

    times = [1.0, 2.0, 3.0, 3.1, 8.0, 9.0, 20.0, 21.0]
    outages = [(2.5, 3.05, "every vehicle silent"), (19.5, None, "bus down")]
    assert outage_marks(times, outages) == [
        "",
        "every vehicle silent",  # the last sample before it: the hole starts here
        "every vehicle silent",  # in the outage
        "every vehicle silent",  # the first sample after it: the hole ends here
        "",
        "bus down",  # before the outage that never ended
        "bus down",  # ... which marks every sample to the end
        "bus down",
    ]
    # a hole with no sample in it: the samples either side of it
    assert outage_marks([1.0, 2.0, 9.0, 10.0], [(3.0, 8.0, "x")]) == ["", "x", "x", ""]
    assert outage_marks(times, []) == [""] * len(times)
