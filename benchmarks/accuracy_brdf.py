"""The sky's term of a ground reflectance (issue 28) in view bands against a per-pixel brute
force, under a leafy canopy, for several views, suns and band tolerances.

    python benchmarks/accuracy_brdf.py [--config configs/lawn-hotspot.yaml [--samples 24]]

First, open ground (no canopy) as tests/test_brdf.py has it: a 48 x 32 camera 1.7 m up with a
70-degree field looking down the sun's rays, the CIE clear sky (sun at 30 degrees) on a 96 x 96
raster to 76 degrees; the rendered radiance (``brdf_view.ground_radiance`` over constant rasters)
against sum_i f_r(V, L_i) e_i + f_r(V, L_sun) E_sun at five pixels' own views.

A 24 x 24 random leaf mask (60% leaves, 0.25 m pixels, 4 m up) over a 40 x 40 ground window
(10 m), the CIE clear sky (turbidity 3) on a sky square of 75 degrees, a camera 1.7 m up at a
corner, at an edge or over the middle of the window, so that its views span view zeniths of
6-83 degrees and 90, 180 or 360 degrees of azimuth. Brute force: at every 4th pixel in each
direction, the sky raster weighted by the shape at that pixel's own view and correlated for it
alone (``brdf_bands.weighted_raster``, ``shadow.ground_isolated``). Banded: ``brdf_bands.choose_bands``
at each tolerance, the bands' correlations (the colour bands' in every channel, the
others' of the sky's channels' sum) blended by ``brdf_bands.banded_sky`` with ``brdf_bands.sky_ratio``.
Printed: the largest relative error over the sampled pixels and channels, and Lambert's.

With ``--config``: the same on a shipped config's own sky raster, canopy spectrum and camera,
frame 0, first layer (isolated layouts): ``--samples`` ground cells the camera sees, spread
near to far and left to right, each brute-forced (its view's weighted raster correlated over
the whole coarse window), against the bands at each tolerance as the frame makes them (on
``shadow.coarser_isolated``'s blocks), read bilinearly at the same cell; at the default
tolerance also the blend alone: the same bands correlated at full resolution and taken at the
cells themselves, so that the blocks' and the read's part of the error shows apart.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.camera import brdf_view as brdf_camera
from pipeline.config.settings import BrdfConfig
from pipeline.config.vocabulary import BRDF_PRESETS
from pipeline.core.geometry import Grid
from pipeline.ground import brdf as R
from pipeline.ground import (
    brdf_bands,
    shadow,
)
from pipeline.sky.procedural import ProceduralSky
from pipeline.sky.sun_disc import SunDisc

N, STEP = 40, 4
CASES = (  # sun azimuth, elevation [deg]; camera position [m]
    (315.0, 30.0, (-5.0, 5.0, 1.7)),
    (135.0, 30.0, (-5.0, 5.0, 1.7)),
    (90.0, 50.0, (-5.0, 0.0, 1.7)),
    (315.0, 15.0, (0.0, 0.0, 1.7)),
)
TOLERANCES = (0.01, 0.02, 0.05, 1.0)


def _at_cells(term, window, cells) -> np.ndarray:
    """A term's raster (``GroundResult``) at the centres of the window's cells (rows, cols),
    bilinearly, edges held: (n, channels)."""
    from scipy.ndimage import map_coordinates

    x, y = window.ground_from_raster(*cells)
    r, c = term.grid.raster_from_ground(x, y)
    return np.stack([map_coordinates(term.irradiance[..., k], [r, c], order=1, mode="nearest")
                     for k in range(term.irradiance.shape[-1])], axis=-1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config")
    parser.add_argument("--samples", type=int, default=24)
    args = parser.parse_args()
    if args.config:
        config_case(args.config, args.samples)
    else:
        open_ground()
        window_cases()


def open_ground() -> None:
    """Open ground: rendered radiance against the quadrature at five pixels (see the module's text)."""
    from pipeline.camera import pinhole as cam
    from pipeline.texture import mipmap as texture

    def constant(value):
        value = np.asarray(value, np.float32).reshape(-1)
        value = np.broadcast_to(value, (3,)) if value.size == 1 else value
        grid = Grid((-1.0, 1.0), 1.0, (2, 2))
        return texture.mipmap(np.broadcast_to(value, (2, 2, value.size)).copy(), grid, outside="constant", value=value)

    sky = ProceduralSky(turbidity=3.0, sun=SunDisc(np.radians(315.0), np.radians(30.0)))
    raster = sky.raster(Grid((-4.0, 4.0), 8.0 / 96, (96, 96)))
    e_sun = np.asarray(sky.undimmed_sun_irradiance(), dtype=np.float64)
    view = cam.Camera.look_at((0.0, 0.0, 1.7), (6.0, -6.0, 0.0), vertical_fov=np.radians(70.0), width=48, height=32)
    views = brdf_camera.view_vectors(view)
    dirs = R.cell_directions(raster.grid).reshape(-1, 3)
    e = raster.weighted.reshape(3, -1).astype(np.float64)
    rows, _ = cam.rows_seeing_ground(view)
    picks = [(rows[-1], 24), (rows[-1], 2), (rows[len(rows) // 2], 40), (rows[len(rows) // 4], 10), (rows[2], 30)]
    for name, (model, parameters) in BRDF_PRESETS.items():
        brdf = BrdfConfig(model, tuple(parameters.items()), name)
        bands = brdf_bands.choose_bands(brdf, raster, views)
        band_sky = [R.shape(brdf, v, dirs) @ (e.T if k in bands.colours else e.sum(axis=0))
                    for k, v in enumerate(bands.directions())]
        radiance = brdf_camera.ground_radiance(view, brdf, constant(1.0), sun=(constant(e_sun),),
                                     sky_maps=(constant(np.concatenate(np.atleast_1d(*band_sky))),),
                                     bands=bands, sun_direction=sky.sun_direction,
                                     raster=raster)
        errors, lambert = [], []
        for r, c in picks:
            v = views[(r - rows[0]) * view.width + c]
            want = (R.shape(brdf, v, dirs) @ e.T + R.shape(brdf, v, sky.sun_direction) * e_sun) / np.pi
            errors.append(np.max(np.abs(radiance[r, c] / want - 1)))
            lambert.append(np.max(np.abs((e.sum(axis=1) + e_sun) / np.pi / want - 1)))
        print(f"open ground, {name}: {bands.count} bands; at five views the rendered radiance is within "
              f"{max(errors):.5f} of the quadrature (Lambert's would be {min(lambert):.3f}-{max(lambert):.3f} off)")


def config_case(path: str, samples: int) -> None:
    """The bands against a per-pixel brute force on a config's frame 0 (see the module's text)."""
    import tempfile

    from pipeline.cache import store as cache
    from pipeline.camera import pinhole as camera
    from pipeline.stages.cycle import cycle_item
    from pipeline.stages.ground import render_ground
    from pipeline.stages.plan import plan_run
    from pipeline.stages.resolve import load

    plan = plan_run(load(path))
    brdf, view, layer = plan.ground.brdf, plan.camera, plan.layers[0]
    with tempfile.TemporaryDirectory() as folder:
        store = cache.Cache(Path(folder))
        sky = plan.sky.at(plan.scenes[0])
        ground = render_ground(plan, 0, store=store, workers=2, sky=sky, coarse_sky=True)
        item = cycle_item(plan, 0, 0, store, workers=2)
        raster = ground.coarse_sky.rasters[0]
        views = brdf_camera.view_vectors(view)
        fp, _ = camera.view_footprints(view)
        r, c = plan.window.raster_from_ground(fp.x, fp.y)
        inside = np.flatnonzero((r >= 0) & (c >= 0) & (r <= plan.window.shape[0] - 1) & (c <= plan.window.shape[1] - 1))
        chosen = inside[np.linspace(0, len(inside) - 1, samples).astype(int)]
        cells = np.round(r[chosen]).astype(int), np.round(c[chosen]).astype(int)
        brute = np.stack([shadow.ground_isolated(brdf_bands.weighted_raster(raster, brdf, views[k]), item.coarse,
                                                 layer.coarse, workers=2)[:, i, j]
                          for k, i, j in zip(chosen, *cells)], axis=1)
        lambert = ground.coarse_sky.irradiance[cells].T
        print(f"{path}: {samples} ground cells, view zeniths "
              f"{np.degrees(np.arccos(views[chosen, 2])).min():.0f}-"
              f"{np.degrees(np.arccos(views[chosen, 2])).max():.0f} deg; "
              f"Lambert's sky term off by up to {np.max(np.abs(lambert / brute - 1)):.3f}")
        blocks = brdf_bands.summed_blocks(raster, brdf_bands.band_factor(plan))  # as the frame takes it
        clamped = R.clamp_view(views)
        angles = np.arccos(clamped[:, 2]), np.arctan2(clamped[:, 0], clamped[:, 1])
        for tolerance in TOLERANCES:
            bands = brdf_bands.choose_bands(brdf, blocks, views, tolerance=tolerance)
            terms = _frame_terms(plan, sky, store, bands, ground)
            weights = bands.weights(*angles).astype(np.float32)[:, chosen]
            ratio = brdf_bands.sky_ratio(brdf, blocks, bands, views)[:, chosen]
            at_cells = lambda t: _at_cells(t, plan.window, cells)  # noqa: E731 -- the terms' grid may be coarser
            colours = np.stack([at_cells(terms[c]).T for c in bands.colours])
            banded = brdf_bands.banded_sky(bands, colours, np.stack([at_cells(t).sum(axis=-1) for t in terms]),
                                           weights, ratio)
            worst = np.argmax(np.abs(banded / brute - 1).max(axis=0))
            print(f"    worst cell: view zenith {np.degrees(np.arccos(views[chosen[worst], 2])):.1f} deg, "
                  f"sky term {brute[1, worst]:.3f} of open {raster.irradiance[1]:.3f}, banded {banded[1, worst]:.3f}")
            print(f"  tolerance {tolerance:g}: {bands.count} bands (bound {bands.error:.4f} over the sampled "
                  f"views), largest error {np.max(np.abs(banded / brute - 1)):.4f}, "
                  f"median {np.median(np.abs(banded / brute - 1)):.4f}", flush=True)
            if tolerance == brdf_bands.BAND_TOLERANCE:
                # the blend alone: the same bands correlated over the whole coarse window (no blocks
                # of shadow.coarser_isolated) and taken at the cells themselves (no bilinear read)
                full = [shadow.ground_isolated(
                    brdf_bands.weighted_raster(raster, brdf, d, summed=k not in bands.colours),
                    item.coarse, layer.coarse, workers=2)[(slice(None), *cells)]
                    for k, d in enumerate(bands.directions())]
                alone = brdf_bands.banded_sky(bands, np.stack([full[c] for c in bands.colours]),
                                              np.stack([f.sum(axis=0) for f in full]), weights, ratio)
                print(f"    the blend alone (full-resolution terms at the cells): largest error "
                      f"{np.max(np.abs(alone / brute - 1)):.4f}, median {np.median(np.abs(alone / brute - 1)):.4f}; "
                      f"the blocks and the read move the result by up to {np.max(np.abs(banded / alone - 1)):.4f}",
                      flush=True)


def _frame_terms(plan, sky, store, bands, ground) -> list:
    """The bands' terms as ``frame.brdf_background`` makes them: the colour bands in every channel,
    the others on the channels' sum."""
    from pipeline.stages.ground import FrameContext, sky_view_terms

    context = FrameContext.of(plan, 0, store=store, workers=2, sky=sky)
    directions, colours = bands.directions(), list(bands.colours)
    others = [b for b in range(bands.count) if b not in colours]
    made = dict(zip(colours, sky_view_terms(context, directions[colours], ground)))
    if others:
        made.update(zip(others, sky_view_terms(context, directions[others], ground, colour=-1)))
    return [made[b] for b in range(bands.count)]


def window_cases() -> None:
    occlusion = (np.random.default_rng(3).random((24, 24)) < 0.6).astype(np.float32)
    window, canopy = Grid((-5.0, 5.0), 0.25, (N, N)), Grid((-3.0, 3.0), 0.25, (24, 24))
    plan = shadow.plan_isolated(window, canopy, height=4.0, alpha=np.radians(75.0))
    spectrum = shadow.occlusion_spectrum(occlusion, plan)
    gx, gy = np.broadcast_arrays(*window.ground_from_raster(np.arange(N)[:, None], np.arange(N)[None, :]))
    sel = (slice(None), slice(1, N, STEP), slice(1, N, STEP))
    print("cells: bands chosen: largest error; the default tolerance is "
          f"{brdf_bands.BAND_TOLERANCE:g}, at most {brdf_bands.MAX_BANDS} bands")
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
                    brute[:, r, col] = shadow.ground_isolated(brdf_bands.weighted_raster(raster, brdf, v[r, col]),
                                                              spectrum, plan)[:, r, col]
            sky_only = shadow.ground_isolated(raster, spectrum, plan)
            lambert = np.max(np.abs(sky_only[sel] / brute[sel] - 1))
            cells = []
            for tolerance in TOLERANCES:
                bands = brdf_bands.choose_bands(brdf, raster, flat, tolerance=tolerance)
                directions = bands.directions()
                colours = np.stack([shadow.ground_isolated(brdf_bands.weighted_raster(raster, brdf, directions[c]),
                                                           spectrum, plan).reshape(3, -1) for c in bands.colours])
                terms = [shadow.ground_isolated(brdf_bands.weighted_raster(raster, brdf, d, summed=True), spectrum,
                                                plan).reshape(-1) for d in directions]
                clamped = R.clamp_view(flat)
                weights = bands.weights(np.arccos(clamped[:, 2]),
                                        np.arctan2(clamped[:, 0], clamped[:, 1])).astype(np.float32)
                banded = brdf_bands.banded_sky(bands, colours, np.stack(terms), weights,
                                               brdf_bands.sky_ratio(brdf, raster, bands, flat)).reshape(3, N, N)
                cells.append(f"{bands.count}: {np.max(np.abs(banded[sel] / brute[sel] - 1)):.4f}")
            turn = np.degrees(np.ptp(np.unwrap(np.arctan2(flat[:, 0], flat[:, 1]))))
            print(f"{name:6s}  {azimuth:3.0f}/{elevation:2.0f}     {camera!s:16s} {turn:5.0f}        "
                  f"{lambert:.3f}    " + "  ".join(f"{cell:9s}" for cell in cells), flush=True)


if __name__ == "__main__":
    main()
