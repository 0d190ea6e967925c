#!/usr/bin/python3
"""Expected image metrics for tests/host/report/test_metrics.cpp, from an independent implementation.

Regenerates the test images from the same integer formulas as the C++ test (make_pair there)
and prints RMSE, PSNR and SSIM as computed by scikit-image:
  structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                        data_range=255, channel_axis=-1)
Run with Debian's python3-skimage (apt-get install -y python3-skimage):
  /usr/bin/python3 tests/host/report/ssim_expected.py
and paste the printed values into kExpected in tests/host/report/test_metrics.cpp.
"""
import math

import numpy as np
import skimage
from skimage.metrics import mean_squared_error, peak_signal_noise_ratio, structural_similarity


def pixel(case, w, h, x, y, c, second):
    """Integer formulas shared with make_pair() in tests/host/report/test_metrics.cpp."""
    if case == "noise":
        a = ((x * 73 + y * 151 + c * 29) ^ (x * y * 7)) & 255
        if not second:
            return a
        return min(255, max(0, a + (x * 11 + y * 17 + c * 5) % 64 - 32))
    if case == "shifted":
        xs = x + 1 if second else x
        return (xs * 6 + y * 2 + c * 40 + (xs * y) // 9) % 256
    if case == "constant":
        return 110 if second else 100
    if case == "blocks":
        v = 40 + 60 * (((x // 4) + (y // 3) + c) % 4)
        if second and (x + 2 * y) % 7 == 0:
            v = 255 - v
        return v
    raise ValueError(case)


def image(case, w, h, second):
    img = np.zeros((h, w, 3), dtype=np.uint8)
    for y in range(h):
        for x in range(w):
            for c in range(3):
                img[y, x, c] = pixel(case, w, h, x, y, c, second)
    return img


CASES = [("noise", 37, 29), ("shifted", 40, 23), ("constant", 11, 11), ("blocks", 64, 48)]

print(f"// scikit-image {skimage.__version__}")
for case, w, h in CASES:
    a, b = image(case, w, h, False), image(case, w, h, True)
    rmse = math.sqrt(mean_squared_error(a, b))
    psnr = peak_signal_noise_ratio(a, b, data_range=255)
    ssim = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                 data_range=255, channel_axis=-1)
    print(f'    {{"{case}", {w}, {h}, {rmse:.12g}, {psnr:.12g}, {ssim:.12g}}},')
