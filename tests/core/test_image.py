"""rangekit.image.to_grey: the one RGB-to-grey rule (mean of the channels, float32)."""

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.image import to_grey


def test_to_grey_is_the_channel_mean_in_float32():
    rgb = np.random.default_rng(0).integers(0, 256, (4, 5, 6, 3)).astype(np.uint8)
    grey = to_grey(rgb)
    assert grey.shape == (4, 5, 6) and grey.dtype == np.float32
    np.testing.assert_allclose(grey, rgb.astype(np.float64).mean(axis=-1), rtol=1e-6)
    assert np.array_equal(to_grey(np.repeat(rgb[..., :1], 3, axis=-1)), rgb[..., 0].astype(np.float32))
    with pytest.raises(InputError, match=r"found shape \(5, 6\)"):
        to_grey(rgb[0, :, :, 0])
