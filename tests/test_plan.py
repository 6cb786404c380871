import numpy as np
import pytest
from scenes import config_of, tiny_grove

from pipeline.core.geometry import offset_direction
from pipeline.sky import ephemeris
from pipeline.stages.scene import scene_at


@pytest.mark.parametrize("azimuth,elevation", [(180.0, 60.0), (95.0, 20.0), (300.0, 75.0)])
def test_moon_offsets_invert_the_ephemeris_tangent_plane(azimuth, elevation):
    """An explicit moon offset from the sun lands where ephemeris.moon_offset_from_sun,
    an independent forward map, says it is."""
    sun = ephemeris.BodyPosition(np.radians(azimuth), np.radians(elevation), 0.0047)
    for dx, dy in [(0.01, 0.0), (-0.004, 0.007), (0.0, -0.009)]:
        az, el = offset_direction(sun.azimuth, sun.elevation, dx, dy)
        moon = ephemeris.BodyPosition(az, el, 0.0047)
        assert ephemeris.moon_offset_from_sun(sun, moon) == pytest.approx((dx, dy), abs=1e-12)


def test_scene_moves_the_moon_across_the_frames(tmp_path):
    config = config_of(tiny_grove(**{"sky.moon": {"offset_start": [-0.6, 0.0],
                                                  "offset_end": [0.6, 0.0]}}), tmp_path)
    first, middle, last = (scene_at(config, f) for f in (0, 3, 5))
    sun = ephemeris.BodyPosition(first.sun.azimuth, first.sun.elevation, 0.0)

    def offset(scene):
        moon = ephemeris.BodyPosition(scene.moon.azimuth, scene.moon.elevation, 0.0)
        return np.degrees(ephemeris.moon_offset_from_sun(sun, moon))

    assert offset(first) == pytest.approx((-0.6, 0.0), abs=1e-9)
    assert offset(last) == pytest.approx((0.6, 0.0), abs=1e-9)
    assert offset(middle)[0] == pytest.approx(-0.6 + 1.2 * 3 / 5, abs=1e-9)
    assert last.time == pytest.approx(5 / 24)
