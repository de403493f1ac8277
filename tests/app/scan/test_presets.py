"""Named pattern sets and the fastest set for a stated accuracy (rangekit/app/scan/presets.py, issue 51 Deliver 2)."""

from __future__ import annotations

import pytest

from rangekit.coded.patterns import PatternSpec
from rangekit.app.scan.presets import MEASURED, MEASURED_OBJECTS, PRESETS, fastest_for, preset_of, preset_spec
from rangekit.errors import OptionError


def _worst(name: str) -> float:
    return max(r[0] for r in MEASURED[name][1].values())


def test_every_measured_set_is_a_preset_measured_on_every_object_with_its_frame_count():
    assert set(MEASURED) == set(PRESETS)
    for name, (frames, per) in MEASURED.items():
        assert set(per) == set(MEASURED_OBJECTS), name
        assert preset_spec(name, (1280, 800)).n_frames == frames, name
        assert all(0 < rms <= p95 and 0 < complete <= 1 for rms, p95, complete in per.values()), name


@pytest.mark.parametrize("size", [(1280, 800), (320, 200), (1024, 768)])
def test_a_preset_fits_any_projector_and_is_found_again_from_its_spec(size):
    for name in PRESETS:
        spec = preset_spec(name, size)
        assert (spec.width, spec.height) == size
        assert preset_of(PatternSpec.from_dict(spec.to_dict())) == name
    assert preset_of(preset_spec("phase-3f", size).__class__("graycode", *size)) is None


def test_the_fastest_set_meets_the_target_and_no_set_of_fewer_frames_does():
    for target in sorted({_worst(n) for n in MEASURED}):
        name = fastest_for(target)
        assert _worst(name) <= target
        assert all(_worst(other) > target for other in MEASURED if MEASURED[other][0] < MEASURED[name][0])
    loosest = fastest_for(10.0)
    assert MEASURED[loosest][0] == min(frames for frames, _ in MEASURED.values())


def test_a_target_no_set_meets_names_the_best_measured():
    best = min(MEASURED, key=_worst)
    with pytest.raises(OptionError, match=rf"target_mm.*{best!r} at {_worst(best):.4f} mm"):
        fastest_for(_worst(best) * 0.99)


def test_an_unknown_preset_names_the_known_ones():
    with pytest.raises(OptionError, match="unknown pattern preset 'fast'; known: .*phase-3f"):
        preset_spec("fast", (1280, 800))
