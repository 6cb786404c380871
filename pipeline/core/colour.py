"""Colour constants of the linear Rec.709 RGB the renderer works in (D65 white).

One home for the colour-space numbers that the sky, the clear-sky shapes, the canopy and the
composite share.
"""

from __future__ import annotations

import numpy as np

__all__ = ["REC709_LUMINANCE", "XYZ_TO_REC709"]

REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
"""Luminance weights of linear Rec.709 RGB, (3,) float32: Y = REC709_LUMINANCE @ rgb. [1]"""

XYZ_TO_REC709 = np.array(
    [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]]
)
"""CIE XYZ to linear Rec.709 RGB (D65 white), IEC 61966-2-1: (3, 3) float64, rgb = XYZ_TO_REC709 @ xyz. [1]"""
