"""The fused int16 census-SGM kernel (rangekit.stereo._sgm) against a plain numpy transcription of
Hirschmuller 2008: census cost, 8 (or 4) path recurrences, winner-take-all with the uniqueness test, the
right image's winner and the left-right check. Integer costs make the answer exact, so the disparities
must agree to the bit; also at the int16 limits (64-bit census, P2 = 4000) and for 1 and 2 threads."""

import numba
import numpy as np
import pytest

from rangekit.stereo import _kernels, sgm_disparity

BAD = np.nan


def _census(img, w, h):
    H, W = img.shape
    pad = np.pad(img, ((h // 2, h // 2), (w // 2, w // 2)), mode="edge")
    code = np.zeros(img.shape, np.uint64)
    for j in range(h):
        for i in range(w):
            if (i, j) != (w // 2, h // 2):
                code = (code << np.uint64(1)) | (pad[j:j + H, i:i + W] < img).astype(np.uint64)
    return code


def _popcount(v):
    return np.array([bin(int(a)).count("1") for a in v.ravel()], np.int64).reshape(v.shape)


def _reference(L, R, D, window, P1, P2, paths, uniqueness, lr):
    """Integer disparities (NaN where invalid) and confidence, straight from the paper's equations."""
    H, W = L.shape
    cl, cr = _census(L, *window), _census(R, *window)
    C = np.full((H, W, D), window[0] * window[1] - 1, np.int64)
    for k in range(D):
        C[:, k:, k] = _popcount(cl[:, k:] ^ cr[:, :W - k])
    dirs = [(1, 0), (0, 1), (1, 1), (-1, 1)][:paths // 2]
    S = np.zeros((H, W, D), np.int64)
    for dx, dy in dirs + [(-a, -b) for a, b in dirs]:
        Lr = np.zeros((H, W, D), np.int64)
        forward = dy > 0 or (dy == 0 and dx > 0)
        ys = range(H) if forward else range(H - 1, -1, -1)
        xs = list(range(W)) if forward else list(range(W - 1, -1, -1))
        for y in ys:
            for x in xs:
                yp, xp = y - dy, x - dx
                if not (0 <= yp < H and 0 <= xp < W):
                    Lr[y, x] = C[y, x]
                    continue
                p = Lr[yp, xp]
                m = p.min()
                up = np.r_[p[1:], 1 << 40]
                down = np.r_[1 << 40, p[:-1]]
                Lr[y, x] = C[y, x] + np.minimum(np.minimum(p, np.minimum(up, down) + P1), m + P2) - m
        S += Lr
    disp = np.full((H, W), np.nan, np.float32)
    conf = np.zeros((H, W), np.float32)
    dint = np.full((H, W), -1, np.int64)
    for y in range(H):
        for x in range(W):
            s = S[y, x, :min(D, x + 1)]
            kb = int(np.argmin(s))
            far = np.r_[s[:max(kb - 1, 0)], s[kb + 2:]]
            second = far.min() if far.size else s[kb]
            conf[y, x] = 1.0 - s[kb] / second if second > 0 else 0.0
            if s[kb] <= (1.0 - uniqueness) * second:
                dint[y, x] = kb
                disp[y, x] = kb
    if lr:
        dright = np.full((H, W), -(1 << 30), np.int64)
        for y in range(H):
            for xr in range(W):
                ks = np.arange(D)[xr + np.arange(D) < W]
                if ks.size:
                    dright[y, xr] = ks[np.argmin(S[y, xr + ks, ks])]
        for y in range(H):
            for x in range(W):
                if dint[y, x] >= 0 and abs(dright[y, x - dint[y, x]] - dint[y, x]) > 1:
                    disp[y, x] = np.nan
    return disp, conf


def _pair(H=14, W=40, shift=5, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 9, (H, W + shift)).astype(np.float32)  # many ties: equal is not darker
    return base[:, :W], base[:, shift:W + shift]


@pytest.mark.parametrize("paths, P1, P2, window, lr, D, W", [
    (8, 10, 120, (9, 7), True, 16, 40), (4, 3, 40, (5, 3), False, 16, 40), (8, 30, 4000, (13, 5), True, 16, 40),
    (8, 10, 120, (9, 7), True, 48, 61), (4, 10, 120, (9, 7), True, 48, 61)])
def test_fused_kernel_matches_the_equations(paths, P1, P2, window, lr, D, W):
    """Also at 48 disparities (padded to 64 lanes inside the kernel) and an odd width (rows go in pixel pairs)."""
    L, R = _pair(W=W)
    ref_d, ref_c = _reference(L, R, D, window, P1, P2, paths, 0.05, lr)
    got = sgm_disparity(L, R, num_disparities=D, window=window, P1=P1, P2=P2, paths=paths, prefilter=0,
                        subpixel="none", median=False, lr_max_diff=1 if lr else -1)
    np.testing.assert_array_equal(got.disparity, ref_d)
    ok = np.isfinite(ref_d)
    assert ok.mean() > 0.5  # the shift is found, the comparison is not one of empty maps
    assert np.nanmedian(ref_d[:, 12:]) == 5
    np.testing.assert_allclose(got.confidence[ok], np.clip(ref_c[ok], 0, 1), rtol=0, atol=1e-6)


def test_same_disparities_on_one_and_two_threads():
    L, R = _pair(60, 120, 9, seed=3)
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = sgm_disparity(L, R, num_disparities=32)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = sgm_disparity(L, R, num_disparities=32)
    finally:
        numba.set_num_threads(n)
    np.testing.assert_array_equal(one.disparity, two.disparity)
    np.testing.assert_array_equal(one.confidence, two.confidence)


def test_median_network_matches_nanmedian():
    """The 3 x 3 median (median-of-9 network where all 9 are valid) against numpy's nanmedian."""
    rng = np.random.default_rng(2)
    d = (rng.integers(0, 200, (31, 47)) / 4).astype(np.float32)  # quarter pixels: exact means
    d[rng.random(d.shape) < 0.15] = np.nan
    out = np.empty_like(d)
    _kernels.median3(d, out)
    pad = np.pad(d, 1, constant_values=np.nan)
    win = np.stack([pad[j:j + 31, i:i + 47] for j in range(3) for i in range(3)])
    with np.errstate(all="ignore"):
        ref = np.where(np.isnan(d), np.nan, np.nanmedian(win, axis=0)).astype(np.float32)
    np.testing.assert_array_equal(out, ref)
