"""Physical constants shared by several modules, as plain floats.

Only ``math`` is imported here, so that ``parse`` can read these without importing a physics
module. Each value has one home: the modules that need it import it from here.
"""

from __future__ import annotations

import math

__all__ = ["SUN_RADIUS_ARCSEC", "SUN_ANGULAR_RADIUS", "SUN_RADIUS_DEG"]

SUN_RADIUS_ARCSEC = 959.63
"""Mean angular radius of the sun at 1 au, the eclipse-prediction value (Espenak & Meeus 2006,
*Five Millennium Canon of Solar Eclipses*, NASA/TP-2006-214141, section 1.2). [arcsec]"""

SUN_ANGULAR_RADIUS = math.radians(SUN_RADIUS_ARCSEC / 3600.0)
"""``SUN_RADIUS_ARCSEC`` in radians. [rad]"""

SUN_RADIUS_DEG = 0.2666
"""The config's default angular radius of a sun given by angles: ``SUN_RADIUS_ARCSEC`` rounded
to 0.2666 deg (0.266564 deg exactly); rendered frames depend on this rounded value. [deg]"""
