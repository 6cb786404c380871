"""The RPV model against the RAMI-IV benchmark's own tabulations of it (JRC, RAMI-IV, abstract
canopies, anisotropic background: the files rpv_RHO_K_THETA_SZA*.dat), an independent
implementation: the bidirectional reflectance factor at view zenith angles 0-75 degrees and
relative azimuths 0-180, printed to 4 decimals. RAMI counts the relative azimuth from the
forward direction: 180 degrees is the sun's side (the hot spot)."""

import numpy as np
import pytest

from pipeline.config.settings import BrdfConfig
from pipeline.ground.brdf import reflectance_factor

VIEW_ZENITHS = (0, 15, 30, 45, 60, 75)  # degrees
RELATIVE_AZIMUTHS = (0, 30, 60, 90, 120, 150, 180)  # degrees, 180 on the sun's side

RAMI = {  # (rho, k, theta_HG, rho_HS, sun zenith [deg]) -> BRF rows by view zenith
    (0.10, 0.60, -0.20, 0.10, 20): [
        [0.2316] * 7,
        [0.1990, 0.2019, 0.2105, 0.2243, 0.2418, 0.2608, 0.2733],
        [0.1739, 0.1779, 0.1898, 0.2092, 0.2344, 0.2610, 0.2760],
        [0.1573, 0.1616, 0.1744, 0.1952, 0.2216, 0.2464, 0.2574],
        [0.1515, 0.1558, 0.1685, 0.1891, 0.2144, 0.2371, 0.2465],
        [0.1660, 0.1704, 0.1835, 0.2043, 0.2293, 0.2510, 0.2598]],
    (0.70, 0.95, 0.10, 0.70, 50): [
        [0.6467] * 7,
        [0.6790, 0.6750, 0.6645, 0.6513, 0.6396, 0.6323, 0.6299],
        [0.7256, 0.7164, 0.6929, 0.6647, 0.6424, 0.6327, 0.6323],
        [0.7856, 0.7703, 0.7317, 0.6869, 0.6534, 0.6460, 0.6685],
        [0.8584, 0.8361, 0.7809, 0.7176, 0.6689, 0.6497, 0.6565],
        [0.9450, 0.9154, 0.8424, 0.7587, 0.6902, 0.6489, 0.6357]],
}


@pytest.mark.parametrize("case", list(RAMI), ids=[f"rho{c[0]}_k{c[1]}_theta{c[2]}_sza{c[4]}" for c in RAMI])
def test_rpv_matches_the_rami_iv_tabulation(case):
    rho, k, theta, hot, sun_zenith = case
    brdf = BrdfConfig("rpv", (("rho0", rho), ("k", k), ("theta", theta), ("rho_c", hot)))
    t0 = np.radians(sun_zenith)
    light = np.array([np.sin(t0), 0.0, np.cos(t0)])  # the sun's azimuth along +x
    zen, rel = np.meshgrid(np.radians(VIEW_ZENITHS), np.radians(RELATIVE_AZIMUTHS), indexing="ij")
    azimuth = np.pi - rel  # RAMI's 180 degrees: the view on the sun's side
    view = np.stack([np.sin(zen) * np.cos(azimuth), np.sin(zen) * np.sin(azimuth), np.cos(zen)], axis=-1)
    ours = reflectance_factor(brdf, view, np.broadcast_to(light, view.shape))
    assert np.abs(ours - np.array(RAMI[case])).max() < 6e-5  # the table's 4 decimals
