import numpy as np
import pytest

from pipeline import ephemeris
from pipeline.render import _offset_direction


@pytest.mark.parametrize("azimuth,elevation", [(180.0, 60.0), (95.0, 20.0), (300.0, 75.0)])
def test_moon_offsets_invert_the_ephemeris_tangent_plane(azimuth, elevation):
    """An explicit moon offset from the sun lands where ephemeris.moon_offset_from_sun,
    an independent forward map, says it is."""
    sun = ephemeris.BodyPosition(np.radians(azimuth), np.radians(elevation), 0.0047)
    for dx, dy in [(0.01, 0.0), (-0.004, 0.007), (0.0, -0.009)]:
        az, el = _offset_direction(sun.azimuth, sun.elevation, dx, dy)
        moon = ephemeris.BodyPosition(az, el, 0.0047)
        assert ephemeris.moon_offset_from_sun(sun, moon) == pytest.approx((dx, dy), abs=1e-12)
