"""rangekit scan --passes: the options' checks, resuming with the session's passes, the report's pass section."""

import numpy as np
import pytest

from rangekit.app.report.passes import passes_section
from rangekit.cli import main
from rangekit.surface.cloud import PointCloud, merge_clouds


@pytest.mark.parametrize("argv, message", [
    (["--passes", "2", "--method", "laser"], "--passes: a laser scan takes one pass, found 2"),
    (["--flipped"], "--flipped confirms, when resuming a multi-pass scan"),
    (["--passes", "9"], "argument --passes: expected an integer in 1..8, found '9'"),
])
def test_bad_pass_options_exit_2(tmp_path, capsys, argv, message):
    try:
        code = main(["scan", "--out", str(tmp_path / "s"), "--no-process", *argv])
    except SystemExit as exc:     # argparse's own refusal
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "s" / "session.json").exists()


def test_resume_keeps_the_sessions_passes(tmp_path):
    from rangekit.app.scan.options import ScanOptions
    from rangekit.app.scan.setup import prepare_scan

    setup = prepare_scan(ScanOptions(out=tmp_path / "s", views=3, passes=2))
    assert setup.n_views == 6 and setup.passes == 2
    assert np.allclose(setup.simulator.pass_motions[0], np.eye(4))
    from rangekit.formats.sessions.session import ScanPlan, Session

    Session.new(tmp_path / "s", ScanPlan(n_views=6, passes=2), setup.spec, setup.rig, capture=setup.capture,
                simulator=setup.simulator).save()
    from rangekit.rig.rig_file import save_rig

    save_rig(setup.rig, tmp_path / "s" / "rig.json")
    again = prepare_scan(ScanOptions(resume=tmp_path / "s"))
    assert again.passes == 2 and again.n_views == 6
    assert np.allclose(again.devices.pass_motions, setup.devices.pass_motions)
    with pytest.raises(Exception, match=r"^passes 1 differs from the session .* which has 2"):
        prepare_scan(ScanOptions(resume=tmp_path / "s", passes=1))
    with pytest.raises(Exception, match=r"^views 6 differs from the session .* which has 3"):
        prepare_scan(ScanOptions(resume=tmp_path / "s", views=6))


def test_the_report_colours_the_cloud_by_pass():
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(3000, 3))
    ball = 0.05 * ball / np.linalg.norm(ball, axis=1, keepdims=True)
    top, bottom = ball[ball[:, 2] > 0], ball[ball[:, 2] <= 0]
    clouds = [PointCloud(top), PointCloud(bottom)]
    merged = merge_clouds(clouds, np.stack([np.eye(4)] * 2))
    html = "".join(passes_section([0, 1], clouds, merged, ball, np.array([0.0, 0.0, 1.0]), (120, 120)))
    assert "<h2>Passes</h2>" in html and html.count("<img") == 3 and "from below: colour = pass" in html
    assert f"pass 1: {len(top) / len(ball):.0%} of the points" in html
    assert passes_section(None, clouds, merged, ball, np.array([0.0, 0.0, 1.0]), (120, 120)) == []
    assert passes_section([0, 0], clouds, merged, ball, np.array([0.0, 0.0, 1.0]), (120, 120)) == []
