"""The one SSIM definition of gsbench (Wang et al. 2004, in the form 3DGS uses): its constants.

Three forms compute it and take their constants from here:
  metrics/image.py      the evaluation metric (numpy/cv2, float64, border "zeropad" or "valid")
  gsbench/train/losses.py     the training loss (PyTorch, differentiable, zero padding)
  gsbench/train/ssim_cpu.py   the training loss's CPU kernel (numba, hand-written backward, zero padding)

SSIM of one channel at a pixel, with mu, sigma^2 and sigma_ab the Gaussian-weighted local means,
population variances and covariance of images a and b:

    ((2 mu_a mu_b + C1) (2 sigma_ab + C2)) / ((mu_a^2 + mu_b^2 + C1) (sigma_a^2 + sigma_b^2 + C2))

with the separable window SSIM_WINDOW x SSIM_WINDOW of the 1-D Gaussian of SSIM_SIGMA (taps
normalised to sum 1), C1 = (K1 L)^2, C2 = (K2 L)^2, data range L = 1; the mean is over pixels and
channels. Border: "zeropad" filters the full H x W map with zeros outside the image (3DGS's
training loss and the metric that 3DGS-family papers report); "valid" (the metric only) keeps the
pixels whose whole window lies inside. The tests check that the three forms agree
(tests/methods/test_ssim_cpu.py, tests/metrics/test_metrics_image.py).
"""
from __future__ import annotations

SSIM_WINDOW = 11                  # window side, pixels (radius SSIM_WINDOW // 2)
SSIM_SIGMA = 1.5                  # the Gaussian's sigma, pixels
SSIM_K1 = 0.01
SSIM_K2 = 0.03
SSIM_DATA_RANGE = 1.0             # images in [0, 1]
SSIM_C1 = (SSIM_K1 * SSIM_DATA_RANGE) ** 2
SSIM_C2 = (SSIM_K2 * SSIM_DATA_RANGE) ** 2
SSIM_BORDERS = ("zeropad", "valid")
SSIM_ZEROPAD = SSIM_BORDERS[0]    # the training form's border, and the metric's default
# The training forms floor the denominator here (>= C1 C2 ~ 9e-8 up to rounding; the floor is hit
# only with C1 = C2 = 0, which tests use); the metric, in float64, floors it at 1e-20.
SSIM_TRAIN_DEN_FLOOR = 1e-12

__all__ = ["SSIM_WINDOW", "SSIM_SIGMA", "SSIM_K1", "SSIM_K2", "SSIM_DATA_RANGE", "SSIM_C1", "SSIM_C2", "SSIM_BORDERS",
           "SSIM_ZEROPAD", "SSIM_TRAIN_DEN_FLOOR"]
