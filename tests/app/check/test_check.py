"""rangekit check: the measured projector latency (within one frame period of the simulator's,
and a scan that uses the written pattern delay records the frames of a latency-free rig), the saturated
fraction against the simulator's noise-free truth on the shiny zoo object, the outputs and the CLI."""

import json

import numpy as np
import pytest

from support.small_rigs import small_projector_rig

from rangekit.app.acquire.acquire import acquire
from rangekit.app.check.steps import auto_exposures, pattern_delay_for
from rangekit.app.check.run import check_simulated, simulated_check_rig, write_check, write_pattern_delay
from rangekit.rig.camera_controls import round_to_refresh
from rangekit.cli import main
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import ScanPlan
from rangekit.io import read_png
from rangekit.rig.rig_file import load_rig, template_rig
from rangekit.sim import SimRig, default_scene
from rangekit.sim.devices import sim_rig as sim_devices
from rangekit.sim.imaging.sensor import Exposure, saturated

LATENCY_S = 0.05


def small_rig():
    return small_projector_rig()


@pytest.fixture(scope="module")
def shiny():
    return default_scene("shiny")


@pytest.fixture(scope="module")
def checked(shiny):
    sim = SimRig(shiny, small_rig(), seed=3, latency_s=LATENCY_S)
    result, images = check_simulated(sim, spec=make_pattern_spec("graycode", (320, 200)))
    return sim, result, images


def test_latency_within_one_frame_period(checked):
    sim, result, _ = checked
    assert len(result.latencies_s) == 3
    assert abs(result.latency_s - LATENCY_S) < result.frame_period_s
    assert result.latency_s >= LATENCY_S            # a frame sees the pattern only after the latency
    assert result.pattern_delay_s == pytest.approx(pattern_delay_for(result.latency_s, result.frame_period_s))
    assert result.pattern_delay_s >= LATENCY_S + result.frame_period_s - 1e-9


def test_saturation_against_the_truth(checked):
    """The truth: the simulator's noise-free white render at the check's exposure, clipped at full scale."""
    sim, result, images = checked
    W, H = sim.projector.resolution
    truth = saturated(sim.renderer().expected(np.full((H, W), 255, np.uint8)), sim.imaging, Exposure())
    true_fraction = truth[images["mask"]].mean()
    assert true_fraction > 0.01                      # the highlights do saturate at the default exposure
    assert abs(result.stats.saturated_fraction - true_fraction) < 0.01
    assert result.stats.channel_saturation == {"grey": result.stats.saturated_fraction}
    # the suggested exposure brings the highlights below full scale
    assert result.suggested_exposure_us < result.exposure_us
    assert not saturated(sim.renderer().expected(np.full((H, W), 255, np.uint8)), sim.imaging,
                         Exposure(result.suggested_exposure_us))[images["mask"]].mean() > 0.01
    assert result.points > 5000 and result.rms_m < 5e-4


def test_a_scan_with_the_written_delay_records_the_latency_free_frames(checked, shiny, tmp_path):
    _, result, images = checked
    rig = simulated_check_rig(SimRig(shiny, small_rig()), result.pattern_delay_s)
    spec = make_pattern_spec("graycode", (320, 200))
    acquire(SimRig(shiny, small_rig()), small_rig(), spec, tmp_path / "plain", plan=ScanPlan(n_views=1))
    acquire(SimRig(shiny, rig, latency_s=LATENCY_S), rig, spec, tmp_path / "late", plan=ScanPlan(n_views=1))
    # and without the delay the latency shows: the frames differ
    acquire(SimRig(shiny, small_rig(), latency_s=LATENCY_S), small_rig(), spec, tmp_path / "bad",
            plan=ScanPlan(n_views=1))
    frames = sorted((tmp_path / "plain" / "view_000").glob("*.png"))
    assert len(frames) == spec.n_frames
    for f in frames:
        assert f.read_bytes() == (tmp_path / "late" / "view_000" / f.name).read_bytes(), f.name
    assert any(f.read_bytes() != (tmp_path / "bad" / "view_000" / f.name).read_bytes() for f in frames)
    names = write_check(tmp_path / "out", result, images, 255.0, rig)
    assert names == ["check.json", "check.png", "rig.json"]
    data = json.loads((tmp_path / "out" / "check.json").read_text())
    for key in ("latency_s", "saturated_fraction", "dark_fraction", "suggested_exposure_us", "channel_saturation",
                "contrast_percentiles"):
        assert key in data
    assert data["flush_frames"] == 0 and data["flush_counts"] == [0, 0, 0]   # the simulator's frames are all fresh
    assert load_rig(tmp_path / "out" / "rig.json").capture["pattern_delay_s"] == result.pattern_delay_s
    png = read_png(tmp_path / "out" / "check.png")
    assert png.shape[0] == 256 and png.shape[1] == 2 * 320 + 320
    assert np.any(np.all(png[:, :320] == (255, 0, 0), axis=2))          # saturated pixels marked red


def test_write_pattern_delay_changes_only_that_field(tmp_path):
    path = tmp_path / "rig.json"
    data = template_rig()
    path.write_text(json.dumps(data))
    write_pattern_delay(path, 0.1333)
    new = json.loads(path.read_text())
    assert new["capture"].pop("pattern_delay_s") == 0.1333
    data["capture"].pop("pattern_delay_s")
    assert new == data


def test_exposure_rounding_and_auto_exposures():
    assert round_to_refresh(8000.0, 120.0) == pytest.approx(1e6 / 120)
    assert round_to_refresh(100.0, 120.0) == pytest.approx(1e6 / 120)      # at least one period
    assert round_to_refresh(8000.0, None) == 8000.0
    assert auto_exposures(2000.0, 30.0) == (2000, 8000, 32000)
    assert auto_exposures(20000.0, 30.0) == (2083, 8333, 33333)            # one frame period at most


def test_cli_check_on_the_simulator(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(sim_devices, "default_rig", small_rig)
    assert main(["check", "--object", "shiny", "--out", str(tmp_path / "c"), "--latency-ms", "50"]) == 0
    out = capsys.readouterr().out
    assert "saturates" in out and "pattern_delay_s set to 0.1" in out
    assert {p.name for p in (tmp_path / "c").iterdir()} == {"check.json", "check.png", "rig.json"}
    assert main(["check", "--rig", str(tmp_path / "c" / "rig.json"), "--seed", "2"]) == 2
    assert "--seed" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["check", "--latency-ms", "-5"])
    assert exc.value.code == 2
