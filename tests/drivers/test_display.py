"""The pygame projector backend, on SDL's dummy video driver (no screen needed)."""

import subprocess
import sys

import numpy as np
import pytest

from rangekit.errors import DeviceError, PatternError
from rangekit.coded.patterns import make_pattern_spec
from rangekit.sim import default_rig

pygame = pytest.importorskip("pygame", reason="optional extra 'display' (pygame) not installed")


@pytest.fixture
def projector(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    from rangekit.drivers.display import PygameProjector

    p = PygameProjector(default_rig().projector, display=0, fullscreen=False)
    yield p
    p.close()


def test_patterns_are_shown_pixel_exact(projector):
    from rangekit.rig import devices

    assert isinstance(projector, devices.Projector)
    spec = make_pattern_spec("graycode", projector.resolution)
    for i in (0, 7, 30):
        frame = spec.frame(i)
        projector.show(frame)
        assert np.array_equal(projector.displayed()[:, :, 0], frame)
        assert projector.shown_at > 0
    colour = make_pattern_spec("debruijn", projector.resolution).frame(0)
    projector.show(colour)
    assert np.array_equal(projector.displayed(), colour)


def test_bad_input_and_missing_display(projector, monkeypatch):
    with pytest.raises(PatternError, match=r"1280x800.*found \(600, 800\)"):
        projector.show(np.zeros((600, 800), np.uint8))
    from rangekit.drivers.display import PygameProjector

    with pytest.raises(DeviceError, match="display 5 does not exist"):
        PygameProjector(default_rig().projector, display=5, fullscreen=False)


def test_import_is_lazy():
    code = "import sys, rangekit.drivers.display; print('pygame' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
