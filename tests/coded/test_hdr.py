"""Multi-exposure (HDR) coded light: capture per exposure (e<us>/ folders, session.json, resume),
the per-pixel merge rule, and the shiny simulated object decoded over >= 95% of its lit pixels."""

import json

import numpy as np
import pytest

from support.small_rigs import small_projector_rig

from rangekit.app.acquire.acquire import acquire
from rangekit.app.process.view_cache import view_cloud
from rangekit.cli import main
from rangekit.coded.hdr import choose_exposure, merge_decodes
from rangekit.coded.patterns import make_pattern_spec
from rangekit.coded.result import DecodeResult
from rangekit.errors import DeviceError
from rangekit.formats.sessions.session import CaptureSettings, ScanPlan, Session
from rangekit.formats.sessions.check import verify_views
from rangekit.sim import SimRig, default_scene
from rangekit.sim.devices import sim_rig as sim_devices

EXPOSURES = (2000, 8000, 32000)


def small_rig():
    return small_projector_rig()


@pytest.fixture(scope="module")
def shiny():
    return default_scene("shiny")


def _result(col: float, white: np.ndarray) -> DecodeResult:
    H, W = white.shape
    f = np.zeros((H, W), bool)
    return DecodeResult(np.full((H, W), col, np.float32), np.full((H, W), np.nan, np.float32),
                        np.ones((H, W), np.float32), f, f, f, f, white=white)


def test_merge_takes_the_longest_unsaturated_exposure():
    short = np.array([[10, 60, 250]], np.uint8)
    long = np.array([[40, 255, 255]], np.uint8)          # 4x: saturated at pixels 1 and 2
    merged, idx = merge_decodes([_result(1.0, short), _result(2.0, long)], [1000, 4000], 255.0)
    assert idx.tolist() == [[1, 0, 0]]
    assert merged.proj_col.tolist() == [[2.0, 1.0, 1.0]]
    assert merged.white.tolist() == [[10, 60, 250]]       # the long exposure's white scaled by 1/4
    # a pixel whose longest unsaturated exposure did not decode falls back to a shorter unsaturated one
    valid = [np.array([[True, True, True]]), np.array([[False, False, False]])]
    assert choose_exposure([short, long], valid, 255.0).tolist() == [[0, 0, 0]]
    with pytest.raises(Exception, match="increasing exposure"):
        merge_decodes([_result(1.0, short), _result(2.0, long)], [4000, 1000], 255.0)


def _lit_object(sim):
    truth = sim.ground_truth()
    table = [i for i, n in enumerate(truth.object_names) if "table" in n or "disc" in n]
    return truth.lit & (truth.object_id >= 0) & ~np.isin(truth.object_id, table)


def test_hdr_decodes_the_shiny_object(shiny, tmp_path):
    """Decoded pixels (a projector column at confidence >= 0.03) of the lit object: three exposures against
    the default one, whose highlights saturate."""
    spec = make_pattern_spec("hybrid", (320, 200))
    rig = small_rig()
    got = {}
    for name, exps in (("one", None), ("hdr", EXPOSURES)):
        sim = SimRig(shiny, rig, seed=1)
        acquire(sim, rig, spec, tmp_path / name, plan=ScanPlan(n_views=1),
                capture=CaptureSettings(bits=8, exposures_us=exps))
        session = Session.load(tmp_path / name)
        assert verify_views(session) == []
        settings = {"method": "auto", **({"exposures_us": list(exps)} if exps else {})}
        _, maps = view_cloud(session.views[0], spec, rig, settings, 255.0, None, 0.0)
        lit = _lit_object(sim)
        decoded = np.isfinite(maps.proj_col) & (maps.confidence >= 0.03)
        truth = sim.ground_truth()
        right = decoded & (np.abs(maps.proj_col - truth.proj_col) < 1.0)
        got[name] = (decoded[lit].mean(), right[lit].mean())
    assert got["hdr"][0] >= 0.95 and got["hdr"][1] >= 0.95
    print(f"decoded / right within 1 px of the lit object: one exposure {got['one']}, three {got['hdr']}")
    data = json.loads((tmp_path / "hdr" / "session.json").read_text())
    assert data["capture"]["exposures_us"] == list(EXPOSURES)
    assert "exposures_us" not in json.loads((tmp_path / "one" / "session.json").read_text())["capture"]
    for e in EXPOSURES:
        assert len(list((tmp_path / "hdr" / "view_000" / f"e{e}").glob("*.png"))) == spec.n_frames
    assert sorted(data["views"][0]["sha256"])[0] == "e2000/000.png"


def test_hdr_resume_records_the_same_bytes(shiny, tmp_path):
    spec = make_pattern_spec("graycode", (320, 200))
    rig, cap, plan = small_rig(), CaptureSettings(bits=8, exposures_us=(4000, 16000)), ScanPlan(n_views=2)
    acquire(SimRig(shiny, rig, seed=2), rig, spec, tmp_path / "whole", plan=plan, capture=cap)
    sim = SimRig(shiny, rig, seed=2)
    sim.inject_fault("camera", after=spec.n_frames * 2 + spec.n_frames + 3)   # in view 1's second exposure
    with pytest.raises(DeviceError, match=r"e16000/frame"):
        acquire(sim, rig, spec, tmp_path / "cut", plan=plan, capture=cap)
    acquire(SimRig(shiny, rig, seed=2), rig, spec, tmp_path / "cut", plan=plan, resume=True)
    for f in sorted((tmp_path / "whole").glob("view_*/e*/*.png")):
        assert f.read_bytes() == (tmp_path / "cut" / f.relative_to(tmp_path / "whole")).read_bytes(), f


def test_cli_exposures(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(sim_devices, "default_rig", small_rig)
    base = ["scan", "--views", "2", "--patterns", "graycode", "--no-process", "--object", "shiny"]
    assert main([*base, "--out", str(tmp_path / "a"), "--exposures", "8000", "2000"]) == 0
    assert Session.load(tmp_path / "a").capture.exposures_us == (2000, 8000)
    assert main([*base, "--out", str(tmp_path / "b"), "--exposures", "auto"]) == 0
    exps = Session.load(tmp_path / "b").capture.exposures_us
    assert len(exps) == 3 and exps[1] == pytest.approx(4 * exps[0], abs=1) and exps[0] < 20000
    assert "--exposures auto" in capsys.readouterr().out
    assert main([*base, "--out", str(tmp_path / "c"), "--exposures", "2000"]) == 2
    assert "2 to 8" in capsys.readouterr().err
