"""A blur that a coarse depth prior is compared through (``prior_blur``, docs/fusion.md).

A monocular network's depth, a sensor's depth at a lower resolution or a depth map upsampled
from a coarse grid is the surface seen through a low-pass filter. Compared pixel by pixel with
the result, such a prior drags the result's detail toward its own blur; compared after the
same blur, it only says what it knows: the low frequencies and the offsets.

:class:`PlaneBlur` is a first-order normalised Gaussian convolution over a mask (Knutsson &
Westin, CVPR 1993): at each pixel, the value at the centre of the plane fitted by weighted
least squares to the mask's values, with Gaussian weights of standard deviation ``sigma``
pixels. Inside the mask it is the plain Gaussian blur (the weights are symmetric about the
centre, so the plane's slopes drop out); at the mask's edge a zeroth-order normalised
convolution (a weighted mean) sits at the centroid of the pixels it averages and biases a
sloped surface by up to ``sigma`` times its slope, which the plane removes (measured on the
fusion benchmark's coarse priors: the first order matches them 5-10x better than the weighted
mean, docs/fusion.md). The filter is linear in the values: three Gaussian filterings of the
masked values and of the values times the column and row, combined with coefficient maps
computed once per mask.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

#: Gaussian support in standard deviations (scipy's ``truncate``).
TRUNCATE = 3.0

#: Tikhonov term on the plane's slopes, relative to a full neighbourhood's second moment
#: (``s0 sigma^2``): a pixel whose neighbourhood is a line or a single pixel falls back toward
#: the weighted mean instead of a singular fit. On a full neighbourhood it moves the slopes by
#: this share, which the symmetric weights make irrelevant to the centre value.
RIDGE = 1e-3


class PlaneBlur:
    """First-order normalised Gaussian convolution over `mask` (module docstring).

    Parameters
    ----------
    mask : (H, W) bool
        The pixels that hold values.
    sigma : float
        Standard deviation of the Gaussian, in pixels (> 0).
    """

    def __init__(self, mask: np.ndarray, sigma: float):
        if not sigma > 0:
            raise ValueError(f"PlaneBlur: `sigma` must be > 0; got {sigma!r}")
        full = np.asarray(mask, bool)
        self.shape = full.shape
        self.sigma = float(sigma)
        H, W = full.shape
        # the filters run on the mask's bounding box padded by the Gaussian's support (the
        # values outside are zeros either way: the same numbers to the last bit), not on the
        # whole image: prior_fit's fit of a blurred disparity to stanford_bunny@front of the
        # discontinuity benchmark (64k pixels in 512 x 612; six blurs) 0.83 -> 0.38 s
        pad = int(TRUNCATE * self.sigma + 0.5) + 1
        rows, cols = np.flatnonzero(full.any(axis=1)), np.flatnonzero(full.any(axis=0))
        if rows.size:
            self._box = (slice(max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, H)),
                         slice(max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, W)))
        else:
            self._box = (slice(0, H), slice(0, W))
        self.mask = full
        self._inside = full[self._box]  # (the mask on the box)
        m = self._inside.astype(float)
        # coordinates about the image's centre (keeps the moments' cancellation small)
        y = (np.arange(H, dtype=float) - 0.5 * H)[self._box[0], None]
        x = (np.arange(W, dtype=float) - 0.5 * W)[None, self._box[1]]
        S = self._filter
        s0, s_x, s_y = S(m), S(m * x), S(m * y)
        s_xx, s_xy, s_yy = S(m * x * x), S(m * x * y), S(m * y * y)
        # moments about each pixel: sum g (x' - x)^a (y' - y)^b over the mask
        a01, a02 = s_x - x * s0, s_y - y * s0
        a11 = s_xx - 2 * x * s_x + x * x * s0
        a22 = s_yy - 2 * y * s_y + y * y * s0
        a12 = s_xy - x * s_y - y * s_x + x * y * s0
        ridge = RIDGE * self.sigma**2 * s0
        a11 = a11 + ridge
        a22 = a22 + ridge
        # first row of the inverse of the symmetric 3 x 3 moment matrix (cofactors)
        c0 = a11 * a22 - a12 * a12
        c1 = a02 * a12 - a01 * a22
        c2 = a01 * a12 - a02 * a11
        det = s0 * c0 + a01 * c1 + a02 * c2
        ok = self._inside & (s0 > 0) & (np.abs(det) > 0)
        det = np.where(ok, det, 1.0)
        c0, c1, c2 = (np.where(ok, c / det, 0.0) for c in (c0, c1, c2))
        # value = c0 b0 + c1 (S(f x) - x b0) + c2 (S(f y) - y b0), b0 = S(f)
        #: (H, W) share of the Gaussian's mass on the mask around each pixel (1 inside, about
        #: 1/2 at a straight edge, 1/4 at a corner)
        self.support = np.zeros(self.shape)
        self.support[self._box] = np.where(self._inside, s0, 0.0)
        self._k0 = c0 - c1 * x - c2 * y
        self._kx, self._ky = c1, c2
        self._x, self._y = x, y

    def _filter(self, a: np.ndarray) -> np.ndarray:
        return ndimage.gaussian_filter(a, self.sigma, mode="constant", truncate=TRUNCATE)

    def __call__(self, values: np.ndarray) -> np.ndarray:
        """The blurred image (H, W) of `values` (H, W) (read on the mask only); NaN outside
        the mask."""
        f = np.where(self._inside, np.asarray(values)[self._box], 0.0)
        S = self._filter
        out = self._k0 * S(f) + self._kx * S(f * self._x) + self._ky * S(f * self._y)
        full = np.full(self.shape, np.nan)
        full[self._box] = np.where(self._inside, out, np.nan)
        return full
