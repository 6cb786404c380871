"""The ground's reflectance against references outside this code: every preset (and every channel
of ``BRDF_CHANNELS``) against NPL's pydirectional RPV, the Ross-Li kernels against its RTLS, and
``sand`` against the Libya-4 spectral table as docs/accuracy.md prints it ("sand: the Libya-4
fit"), weighted by the channels' weights printed beside it."""

import re
from pathlib import Path

import numpy as np
import pytest

from pipeline.config.settings import BrdfConfig
from pipeline.config.vocabulary import BRDF_CHANNELS, BRDF_PRESETS
from pipeline.ground import brdf as R

DOCS = Path(__file__).resolve().parents[1] / "docs" / "accuracy.md"

RPV_SETS = {**{name: p for name, (m, p) in BRDF_PRESETS.items() if m == "rpv"},
            **{f"{name}-{c}": p for name, channels in BRDF_CHANNELS.items() for c, p in channels.items()}}

ROSSLI_SETS = [(0.1, 0.05, 0.02), (0.3, 0.2, 0.1), (0.05, 0.0, 0.04), (0.8, 1.0, 1.0)]


def random_geometry(n, seed, zenith_max=75.0):
    """Unit vectors towards the viewer and the light, and their angles [deg]: zeniths, relative
    azimuth (the light's azimuth less the viewer's: 0 at the hot spot)."""
    rng = np.random.default_rng(seed)
    zv, zl = rng.uniform(0.0, zenith_max, (2, n))
    av, al = rng.uniform(0.0, 360.0, (2, n))

    def unit(z, a):
        z, a = np.radians(z), np.radians(a)
        return np.stack([np.sin(z) * np.cos(a), np.sin(z) * np.sin(a), np.cos(z)], -1)

    return unit(zv, av), unit(zl, al), zv, zl, (al - av) % 360.0


@pytest.mark.parametrize("name", list(RPV_SETS))
def test_rpv_equals_pydirectional(name):
    rpv = pytest.importorskip("pydirectional.brdf_forward_model.RPV")
    p = RPV_SETS[name]
    v, l, zv, zl, raa = random_geometry(200, 3)
    model = rpv.RPVBRDF(sza=zl, vza=zv, raa=raa)
    theirs = model.return_BRF(float(p["rho0"]), float(p["k"]), float(p["theta"]), float(p["rho_c"]))
    ours = R.reflectance_factor(BrdfConfig("rpv", tuple(p.items())), v, l)
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=0.0)


@pytest.mark.filterwarnings("ignore::PendingDeprecationWarning")  # pydirectional's np.matrix
@pytest.mark.parametrize("weights", ROSSLI_SETS)
def test_rossli_equals_pydirectional_rtls(weights):
    rtls = pytest.importorskip("pydirectional.brdf_forward_model.RTLS")
    v, l, zv, zl, raa = random_geometry(200, 4)
    # RossThick, LiSparse-Reciprocal, h/b 2, b/r 1: the MODIS kernels
    model = rtls.RTLSBRDF(sza=zl, vza=zv, raa=raa, HB=2.0, BR=1.0, RossType="Thick",
                          LiType="Sparse", RecipFlag=True)
    theirs = model.return_BRF(*weights)
    ours = R.reflectance_factor(BrdfConfig("rossli", tuple(zip(("f_iso", "f_vol", "f_geo"), weights))), v, l)
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-12)


def docs_table():
    """The Libya-4 rows docs/accuracy.md prints: (n, 5) wavelength [nm], rho0, k, theta, scale (a
    libRadtran brdf_rpv_file's columns) and (n, 4) the R, G, B, Y weights."""
    text = DOCS.read_text(encoding="utf-8")
    start = text.index("| lambda [nm] | rho0 (col 2) | k (col 3) | Theta (col 4) | scale (col 5) |")
    rows = []
    for line in text[start:].splitlines()[2:]:
        if not line.startswith("| "):
            break
        rows.append([float(cell) for cell in line.strip("|").split("|")])
    table = np.array(rows)
    return table[:, :5], table[:, 5:]


def libradtran_rpv(zv, zl, raa, rho0, k, theta, scale):
    """libRadtran's RPV_REFLECTION (sigma = t1 = 0) written with angles [deg]: relative azimuth 0
    at the hot spot, where cos g = 1; scale on the whole BRF, rho0 its hot-spot parameter too."""
    mv, ml = np.cos(np.radians(zv)), np.cos(np.radians(zl))
    tv, tl, cos_phi = np.tan(np.radians(zv)), np.tan(np.radians(zl)), np.cos(np.radians(raa))
    m = (mv * ml * (mv + ml)) ** (k - 1.0)
    cos_g = mv * ml + np.sin(np.radians(zv)) * np.sin(np.radians(zl)) * cos_phi
    f = (1.0 - theta**2) / (1.0 + 2.0 * theta * cos_g + theta**2) ** 1.5
    h = 1.0 + (1.0 - rho0) / (1.0 + np.sqrt(np.maximum(tv**2 + tl**2 - 2.0 * tv * tl * cos_phi, 0.0)))
    return rho0 * m * f * h * scale


def test_the_docs_table_is_the_dimitri_table():
    """The rows the brief quotes from the DIMITRI file (450, 550, 650 nm) are in the table."""
    spectral, weights = docs_table()
    assert spectral[0, 0] == 390 and spectral[-1, 0] == 780 and np.all(np.diff(spectral[:, 0]) == 10)
    for row in ([450, 0.26947, 0.77734, 0.05522, 0.56022], [550, 0.48283, 0.80664, 0.02564, 0.58299],
                [650, 0.77825, 0.90689, 0.01023, 0.56981]):
        np.testing.assert_allclose(spectral[spectral[:, 0] == row[0]][0], row, atol=6e-6)
    np.testing.assert_allclose(weights.sum(axis=0), 1.0, atol=2e-5)
    # read as libRadtran reads it: nadir, sun at 30 degrees, 550 nm
    nadir = libradtran_rpv(0.0, 30.0, 0.0, *spectral[spectral[:, 0] == 550][0, 1:])
    assert nadir == pytest.approx(0.3186, abs=1e-4)


@pytest.mark.parametrize("channel", ["r", "g", "b", "y"])
def test_sand_reproduces_the_libya4_table_within_1_percent(channel):
    spectral, weights = docs_table()
    w = weights[:, "rgby".index(channel)]
    p = BRDF_PRESETS["sand"][1] if channel == "y" else BRDF_CHANNELS["sand"][channel]
    v, l, zv, zl, raa = random_geometry(20, 5)
    table = w @ libradtran_rpv(zv[None], zl[None], raa[None], *(spectral[:, i, None] for i in range(1, 5)))
    ours = R.reflectance_factor(BrdfConfig("rpv", tuple(p.items())), v, l)
    assert np.abs(ours / table - 1.0).max() < 0.01


@pytest.mark.parametrize("name", [n for n in RPV_SETS if n.startswith("sand")])
def test_sand_reflects_at_most_all_light(name):
    b = BrdfConfig("rpv", tuple(RPV_SETS[name].items()))
    zen = np.radians(np.arange(0.0, 90.0, 1.0))
    light = np.stack([np.sin(zen), 0.0 * zen, np.cos(zen)], -1)
    reflectance = R.directional_reflectance(b, light)
    assert np.all((reflectance > 0.0) & (reflectance <= 1.0))


def test_the_docs_name_the_preset():
    """The preset's numbers in docs/accuracy.md's fit table are the vocabulary's."""
    text = DOCS.read_text(encoding="utf-8")
    p = BRDF_PRESETS["sand"][1]
    row = re.search(r"^\| Y \(the preset\) \| ([^|]+)\| ([^|]+)\| ([^|]+)\| ([^|]+)\|", text, re.MULTILINE)
    assert row is not None
    assert [float(x) for x in row.groups()] == [p["rho0"], p["k"], p["theta"], p["rho_c"]]
