"""The ``sand`` preset from Bouvet's Libya-4 spectral RPV model (docs/accuracy.md, "sand: the
Libya-4 fit"): the table reduced to linear Rec.709 RGB and to Y, each refitted with RPV.

    pip install colour-science   # the CIE 1931 2-degree observer and D65 (not a dependency)
    git -C DIMITRI show 23de430:AUX_DATA/PICS_BRDF_data/Libya4_interpolated_RPV_model.txt > libya4.txt
    python benchmarks/fit_sand.py libya4.txt [--table]

The file (ESA's DIMITRI, repository amdilo/DIMITRI at commit 23de430, 390-959 nm by 1 nm) is a
libRadtran ``brdf_rpv_file``: wavelength [nm], rho0, k, theta, scale, so that its BRF is
scale rho0 M F (1 + (1 - rho0) / (1 + G)) (libRadtran's RPV_REFLECTION): in the RAMI form
``ground.brdf`` uses, rho0 = column 2 x column 5 and rho_c = column 2. Rows every 10 nm over
390-780 nm; each channel's weights D65(lambda) times its matching function (x-bar, y-bar, z-bar
through the XYZ to Rec.709 matrix; y-bar for Y), normalised to sum to 1, so that a flat spectrum
keeps its value. Each channel's weighted BRF is fitted by least squares in relative error on a
grid of zeniths 0-80 degrees by 5 and relative azimuths 0-180 by 15. Prints the parameters
(rounded to 5 decimals as in ``vocabulary``), their largest error at 2000 random geometries
(zeniths to 75 degrees), and with ``--table`` the rows docs/accuracy.md holds.
"""

from __future__ import annotations

import sys

import numpy as np

STEP, FIRST, LAST = 10, 390, 780  # [nm]


def rpv(mv, ml, cos_g, big_g, rho0, k, theta, rho_c):
    """RPV's BRF from the geometry's cosines, phase angle and hot-spot distance [1]."""
    minnaert = (mv * ml) ** (k - 1.0) / (mv + ml) ** (1.0 - k)
    phase = (1.0 - theta * theta) / (1.0 + 2.0 * theta * cos_g + theta * theta) ** 1.5
    return rho0 * minnaert * phase * (1.0 + (1.0 - rho_c) / (1.0 + big_g))


def geometry(zenith_v, zenith_l, phi):
    """cos of both zeniths, cos g and G; phi 0 at the hot spot [rad]."""
    mv, ml = np.cos(zenith_v), np.cos(zenith_l)
    cos_g = mv * ml + np.sin(zenith_v) * np.sin(zenith_l) * np.cos(phi)
    tv, tl = np.tan(zenith_v), np.tan(zenith_l)
    return mv, ml, cos_g, np.sqrt(np.maximum(tv * tv + tl * tl - 2.0 * tv * tl * np.cos(phi), 0.0))


def table_rows(path):
    """The table's rows every STEP nm and each channel's weights (R, G, B, Y), rounded as printed."""
    import colour

    table = np.loadtxt(path)
    rows = table[(table[:, 0] >= FIRST) & (table[:, 0] <= LAST) & ((table[:, 0] - FIRST) % STEP == 0)]
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    xyz = np.array([cmfs[w] for w in rows[:, 0]])
    light = np.array([d65[w] for w in rows[:, 0]])[:, None]
    rgb = xyz @ colour.models.RGB_COLOURSPACE_BT709.matrix_XYZ_to_RGB.T
    weights = np.column_stack([rgb, xyz[:, 1]]) * light
    weights /= weights.sum(axis=0)
    return np.round(rows[:, :5], 5), np.round(weights, 6)


def weighted_brf(spectral, weights, geo):
    """(4, n) each channel's BRF at the geometries: the spectral BRFs weighted [1]."""
    rho, k, theta, scale = (spectral[:, i, None] for i in range(1, 5))
    return weights.T @ rpv(*geo, rho * scale, k, theta, rho)


def main(argv):
    from scipy.optimize import least_squares

    spectral, weights = table_rows(argv[0])
    zen, phi = np.radians(np.arange(0.0, 81.0, 5.0)), np.radians(np.arange(0.0, 181.0, 15.0))
    grid = [a.ravel() for a in np.meshgrid(zen, zen, phi, indexing="ij")]
    geo = geometry(*grid)
    target = weighted_brf(spectral, weights, geo)
    rng = np.random.default_rng(1)
    check = geometry(*rng.uniform(0.0, np.radians(75.0), (2, 2000)), rng.uniform(0.0, 2.0 * np.pi, 2000))
    truth = weighted_brf(spectral, weights, check)
    for c, name in enumerate("RGBY"):
        mean = np.average(spectral[:, 1:], axis=0, weights=np.abs(weights[:, c]))
        fit = least_squares(lambda x, t=target[c]: rpv(*geo, *x) / t - 1.0,
                            [mean[0] * mean[3], mean[1], mean[2], mean[0]],
                            bounds=([1e-4, 0.05, -0.99, 1e-4], [1.0, 1.99, 0.99, 1.0]), xtol=1e-14, ftol=1e-14)
        x = np.round(fit.x, 5)
        error = np.abs(rpv(*check, *x) / truth[c] - 1.0).max()
        print(f"{name}: rho0 {x[0]:.5f} k {x[1]:.5f} theta {x[2]:.5f} rho_c {x[3]:.5f}, largest error {error:.4f}")
    if "--table" in argv:
        print("| lambda [nm] | rho0 (col 2) | k (col 3) | Theta (col 4) | scale (col 5) | w_R | w_G | w_B | w_Y |")
        print("|---|---|---|---|---|---|---|---|---|")
        for row, w in zip(spectral, weights):
            print(f"| {row[0]:.0f} | " + " | ".join(f"{v:.5f}" for v in row[1:]) + " | "
                  + " | ".join(f"{v:.6f}" for v in w) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
