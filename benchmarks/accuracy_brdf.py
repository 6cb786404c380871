"""The sky's term of a ground reflectance (issue 28) in view bands against a per-pixel brute
force, under a leafy canopy, for several views, suns and band tolerances.

    python benchmarks/accuracy_brdf.py

A 24 x 24 random leaf mask (60% leaves, 0.25 m pixels, 4 m up) over a 40 x 40 ground window
(10 m), the CIE clear sky (turbidity 3) on a sky square of 75 degrees, a camera 1.7 m up at a
corner, at an edge or over the middle of the window, so that its views span view zeniths of
6-83 degrees and 90, 180 or 360 degrees of azimuth. Brute force: at every 4th pixel in each
direction, the sky raster weighted by the shape at that pixel's own view and correlated for it
alone (``brdf.weighted_raster``, ``shadow.ground_isolated``). Banded: ``brdf.choose_bands``
at each tolerance, the bands' correlations blended by their weights times ``brdf.sky_ratio``.
Printed: the largest relative error over the sampled pixels and channels, and Lambert's.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline import brdf as R  # noqa: E402
from pipeline import shadow  # noqa: E402
from pipeline.config import BrdfConfig  # noqa: E402
from pipeline.geometry import Grid  # noqa: E402
from pipeline.sky import ProceduralSky, SunDisc  # noqa: E402
from pipeline.vocabulary import BRDF_PRESETS  # noqa: E402

N, STEP = 40, 4
CASES = (  # sun azimuth, elevation [deg]; camera position [m]
    (315.0, 30.0, (-5.0, 5.0, 1.7)),
    (135.0, 30.0, (-5.0, 5.0, 1.7)),
    (90.0, 50.0, (-5.0, 0.0, 1.7)),
    (315.0, 15.0, (0.0, 0.0, 1.7)),
)
TOLERANCES = (0.01, 0.02, 0.05, 1.0)


def main() -> None:
    occlusion = (np.random.default_rng(3).random((24, 24)) < 0.6).astype(np.float32)
    window, canopy = Grid((-5.0, 5.0), 0.25, (N, N)), Grid((-3.0, 3.0), 0.25, (24, 24))
    plan = shadow.plan_isolated(window, canopy, height=4.0, alpha=np.radians(75.0))
    spectrum = shadow.occlusion_spectrum(occlusion, plan)
    gx, gy = np.broadcast_arrays(*window.ground_from_raster(np.arange(N)[:, None], np.arange(N)[None, :]))
    sel = (slice(None), slice(1, N, STEP), slice(1, N, STEP))
    print("preset  sun az/el  camera           view azimuths  Lambert  " + "  ".join(f"tol {t:g}" for t in TOLERANCES))
    for name, (model, parameters) in BRDF_PRESETS.items():
        brdf = BrdfConfig(model, tuple(parameters.items()), name)
        for azimuth, elevation, camera in CASES:
            sky = ProceduralSky(turbidity=3.0, sun=SunDisc(np.radians(azimuth), np.radians(elevation)))
            raster = sky.raster(plan.sky)
            c = np.asarray(camera)
            v = np.stack([c[0] - gx, c[1] - gy, np.full(gx.shape, c[2])], axis=-1)
            v /= np.linalg.norm(v, axis=-1, keepdims=True)
            flat = v.reshape(-1, 3)
            brute = np.empty((3, N, N))
            for r in range(1, N, STEP):
                for col in range(1, N, STEP):
                    brute[:, r, col] = shadow.ground_isolated(R.weighted_raster(raster, brdf, v[r, col]),
                                                              spectrum, plan)[:, r, col]
            lambert = np.max(np.abs(shadow.ground_isolated(raster, spectrum, plan)[sel] / brute[sel] - 1))
            cells = []
            for tolerance in TOLERANCES:
                bands = R.choose_bands(brdf, raster, flat, tolerance=tolerance)
                terms = [shadow.ground_isolated(R.weighted_raster(raster, brdf, d), spectrum, plan)
                         for d in bands.directions()]
                weights = bands.weights(np.arccos(R.clamp_view(flat)[:, 2])) * R.sky_ratio(brdf, raster, bands, flat)[None]
                banded = sum(w.reshape(N, N)[None] * t for w, t in zip(weights, terms))
                cells.append(f"{len(bands.zeniths)}: {np.max(np.abs(banded[sel] / brute[sel] - 1)):.4f}")
            turn = np.degrees(np.ptp(np.unwrap(np.arctan2(flat[:, 0], flat[:, 1]))))
            print(f"{name:6s}  {azimuth:3.0f}/{elevation:2.0f}     {str(camera):16s} {turn:5.0f}        "
                  f"{lambert:.3f}    " + "  ".join(f"{cell:9s}" for cell in cells), flush=True)


if __name__ == "__main__":
    main()
