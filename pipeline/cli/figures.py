"""The paper's figures, remade as PNGs (Max 1991, Figs. 4 to 7, 10 to 13 and 16, and S(t)), and
one beyond it: the ground's reflectance, Lambert beside the grass and sand presets.

Every scene is held here as YAML text, copied from ``configs/grove.yaml``,
``configs/grove-point-sun.yaml`` and ``configs/crescents.yaml``, so the figures do not depend on
the files in ``configs/`` (the package may be installed without them). ``preview`` shrinks the
pixels, the leaves (fewer and larger, the same leaf area), the sun window and the camera so that
the whole set takes seconds.

Images follow the rasters' convention (docs/method.md, "Conventions"): north up, east to the right. The two
plots are drawn with matplotlib's object API (``Figure`` and ``FigureCanvasAgg``): no pyplot, no
backend switch, no global state.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from pipeline.cache import store as cache
from pipeline.camera import composite
from pipeline.config.parse import parse_config
from pipeline.config.settings import BrdfConfig, Config
from pipeline.config.vocabulary import BRDF_PRESETS
from pipeline.core import io
from pipeline.core.colour import REC709_LUMINANCE
from pipeline.core.geometry import I0, Grid, projected_solid_angle
from pipeline.sky import ephemeris, procedural
from pipeline.sky.sun_kernel import sun_kernel
from pipeline.stages.cycle import layer_masks
from pipeline.stages.frame import FrameResult, render_frame
from pipeline.stages.plan import RunPlan, plan_run
from pipeline.stages.resolve import resolve
from pipeline.stages.scene import load_sky, scene_at

if TYPE_CHECKING:
    from collections.abc import Callable

    from numpy.typing import ArrayLike

FIGURES = (
    ("fig04-mask.png",
     "Fig. 4: transmittance mask m of the grove's upper canopy plane (8 m): the leaves projected "
     "along the sun, 1 (white) = open sky, north up"),
    ("fig05-sky.png",
     "Fig. 5: the sky on the sky plane z = 1 over the square of half-angle alpha = 80 degrees: "
     "the sun (azimuth 150, elevation 50), blue sky and clouds, north up"),
    ("fig06-sky-raster.png",
     "Fig. 6: the weighted sky raster e = L cos^4(theta) q^2 that is correlated with Fig. 4 "
     "(the sun, thousands of times the brightest cloud, clips to a few white cells), log scale "
     "over the sky's range, hue kept, north up"),
    ("fig07-ground.png",
     "Fig. 7: ground irradiance raster g under the grove and its shadow, 22 m square, north up "
     "(the open sky at 80% grey)"),
    ("fig10-frame.png",
     "Fig. 10: the finished frame: ground (Fig. 7) and sky resampled in perspective, the trees "
     "composited on top"),
    ("fig11-point-sun.png",
     "Fig. 11: the same frame lit by a point sun alone: no sky light, no penumbrae"),
    ("fig12-eclipse-ground.png",
     "Fig. 12: the ground raster of the sun window under an eclipsed sun (S = 0.21): "
     "crescent-shaped spots of light, north up"),
    ("fig13-eclipse-frame.png",
     "Fig. 13: a frame in the partial eclipse, Fig. 12 as its ground"),
    ("fig16-i0.png",
     "Fig. 16: I0(alpha) / pi, the share of a uniform sky's irradiance inside the sky square "
     "of half-angle alpha, with a quadrature over the hemisphere and the paper's 70 degrees"),
    ("sun-fraction.png",
     "S(t): the sun fraction through the total solar eclipse of 2024 April 8 seen from Dallas, "
     "with the contacts C1 to C4"),
    ("brdf-lawn.png",
     "Beyond the paper: the grove's ground with the sun low behind the camera, Lambert's law "
     "(left), the RPV grass preset (middle, ground.brdf: grass) and the sand preset (right, "
     "ground.brdf: sand, Bouvet's Libya-4 fit) at the same exposure: the hot spot round the "
     "antisolar point at the bottom, the grass darker looking towards the sun's side (no trees "
     "in front)"),
)
"""(file name, one-line caption) of every figure, in the order ``write_figures`` writes them."""


# ---------------------------------------------------------------------------------------------
# The scenes
# ---------------------------------------------------------------------------------------------

GROVE = """\
# configs/grove.yaml: dappled shade of a small grove, clouds drifting over the sun.
canopy:
  height: 8.0
  layout: isolated
  trees: {count: 3, seed: 7, crown_radius: 4.0, leaves_per_tree: 12000, leaf_length: 0.08}
  flutter: {cycle: 48, swing: 12.0, twist: 20.0}
  layers: [{height: 8.0}, {height: 6.5}]
sky:
  model: cie
  turbidity: 3.0
  sun: {elevation: 50.0, azimuth: 150.0}
  clouds: {cover: 0.4, scale: 800.0, altitude: 2000.0, wind: [8.0, 2.0], thickness: 1.0}
  alpha: 80.0
ground:
  window: [-14, -7, 8, 15]    # grove.yaml has [-10, -10, 10, 10], which cuts the shadow off
  pixel: 0.025
  sun_window: [-4, -4, 4, 4]
  sun_pixel: 0.01
camera: {position: [-15.95101705184504, 7.4380814066363135, 1.7], look_at: [0.0, 0.0, 3.6]}
animation: {frames: 240, fps: 24}
"""

CRESCENTS = """\
# configs/crescents.yaml: crescent suns under a dense grove during a partial eclipse.
canopy: {height: 8.0, layout: isolated, flutter: {cycle: 48, swing: 12.0, twist: 20.0},
         trees: {count: 3, seed: 7, crown_radius: 4.0, leaves_per_tree: 90000, leaf_length: 0.08}}
sky: {model: cie, turbidity: 3.0, sun: {elevation: 60.0, azimuth: 180.0}, alpha: 80.0,
      moon: {offset_start: [0.25, 0.12], offset_end: [0.1, 0.05]}}
ground:
  window: [-8, -8, 8, 8]
  pixel: 0.02
  sun_window: [-2, 0, 2, 4]
camera:
  position: [0.0, -0.8, 1.7]
  look_at: [0.0, 1.2, 0.0]
  fov: 50.0
  exposure: 1.5
animation: {frames: 48, fps: 24}
"""

DALLAS_2024 = """\
# The total solar eclipse of 2024 April 8 from Dallas, one output frame a minute.
sky:
  model: cie
  turbidity: 3.0
  site: {latitude: 32.7767, longitude: -96.7970, elevation: 140.0}
  time: {start: "2024-04-08T17:10:00Z", end: "2024-04-08T20:15:00Z"}
animation: {frames: 186, fps: 24}
"""

POINT_SUN = {"sky": {"sun": {"elevation": 50.0, "azimuth": 150.0, "radius": 0.005}, "skylight": 0.0,
                     "clouds": None}}
"""configs/grove-point-sun.yaml: the grove lit by a point sun alone (the paper's Fig. 11), as
its changes to the grove (None: a key removed)."""

LAWN = {"sky": {"sun": {"elevation": 25.0, "azimuth": 295.0}, "clouds": None},
        "ground": {"brdf": "grass"}, "camera": {"look_at": [0.0, 0.0, 0.3]}, "foreground": {"model": "none"}}
"""configs/lawn-hotspot.yaml's idea on the grove: the sun low behind the camera, the RPV grass
preset, the camera looking down so that the antisolar point (25 degrees below the horizon) is
in the picture; no trees in front (their passes do not show the ground's reflectance)."""

SCENES: dict[str, str | tuple[str, dict[str, Any]]] = {
    "grove": GROVE, "point-sun": (GROVE, POINT_SUN), "crescents": CRESCENTS, "dallas-2024": DALLAS_2024,
    "lawn": (GROVE, LAWN)}
"""Each scene the figures use, by name: its YAML text, or (text, changes to it)."""

_PREVIEW_GROVE = {
    "canopy": {"trees": {"leaves_per_tree": 3000, "leaf_length": 0.16}},
    "ground": {"pixel": 0.1, "sun_pixel": 0.04},
    "camera": {"resolution": [320, 180]},
}
PREVIEW: dict[str, dict[str, Any]] = {
    "grove": _PREVIEW_GROVE,
    "point-sun": _PREVIEW_GROVE,
    "lawn": _PREVIEW_GROVE,
    "crescents": {
        "canopy": {"trees": {"leaves_per_tree": 22500, "leaf_length": 0.16}},
        "ground": {"pixel": 0.08, "sun_window": [-1, 0.5, 1, 2.5]},
        "camera": {"resolution": [320, 180]},
    },
    "dallas-2024": {"animation": {"frames": 38}},
}
"""Changes that make each scene quick, merged into its YAML by ``preview=True``: 4x pixels
(the eclipse keeps its default sun pixel, so the disc still spans 16 cells and the crescents
show, over a 2 m sun window), a quarter of the leaves at twice the length (the same leaf area),
a 320 x 180 camera, one S(t) sample every 5 minutes."""


def scene_config(name: str, *, preview: bool = False) -> Config:
    """The Config of a scene, from its YAML text, validated and resolved as a config file is.

    Parameters
    ----------
    name : str
        A key of SCENES.
    preview : bool
        Merge in PREVIEW[name].

    Returns
    -------
    settings.Config
        The resolved config.
    """
    scene = SCENES[name]
    text, changes = scene if isinstance(scene, tuple) else (scene, {})
    data = _merged(yaml.safe_load(text), changes)
    if preview:
        data = _merged(data, PREVIEW.get(name, {}))
    return resolve(parse_config(data, Path("."), name=name))


def _merged(base: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``changes`` merged in, mapping by mapping, a key whose change is None
    removed (neither is mutated)."""
    out = copy.deepcopy(base)
    for key, value in changes.items():
        if value is None:
            out.pop(key, None)
        elif isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


# ---------------------------------------------------------------------------------------------
# Pure pictures
# ---------------------------------------------------------------------------------------------


def sky_plane_image(sky: procedural.ProceduralSky, *, alpha: float, size: int) -> np.ndarray:
    """The sky on the sky plane z = 1 (Max 1991, Fig. 5).

    Over the square |s|_inf <= tan(alpha), north up, east to the right (the rasters' layout, as if
    seen from above through the plane). Clouds are filtered over each cell; the sun disc is added
    as the cos^4-weighted mean radiance of the cells it covers.

    Parameters
    ----------
    sky : procedural.ProceduralSky
        The sky.
    alpha : float
        Half-angle of the sky square [rad].
    size : int
        Cells a side [1].

    Returns
    -------
    ndarray, shape (size, size, 3), float32
        Radiance [kcd/m^2].
    """
    half = np.tan(alpha)
    grid = Grid((-half, half), 2.0 * half / size, (size, size))
    x, y = grid.ground_from_raster(np.arange(size)[:, None], np.arange(size)[None, :])
    s = np.stack(np.broadcast_arrays(x, y), axis=-1)
    image = np.asarray(sky.radiance(s, footprint=grid.pixel), dtype=np.float64)
    kernel = sun_kernel(sky, grid.pixel)
    weights = projected_solid_angle(kernel.grid)
    _add_at_offset(image, np.moveaxis(kernel.weighted, 0, -1) / weights[..., None], kernel.grid, grid)
    return image.astype(np.float32)


def _add_at_offset(target: np.ndarray, block: np.ndarray, block_grid: Grid, grid: Grid) -> None:
    """Add ``block`` (rows, cols, ...) on ``block_grid`` into ``target`` on ``grid``, the two
    grids on the same lattice; the part outside ``target`` is dropped."""
    r0, c0 = (int(round(v)) for v in grid.raster_from_ground(*block_grid.ground_from_raster(0, 0)))
    rows, cols = block.shape[:2]
    a0, b0 = max(r0, 0), max(c0, 0)
    a1, b1 = min(r0 + rows, target.shape[0]), min(c0 + cols, target.shape[1])
    if a1 > a0 and b1 > b0:
        target[a0:a1, b0:b1] += block[a0 - r0:a1 - r0, b0 - c0:b1 - c0]


def weighted_sky_raster(sky: procedural.ProceduralSky, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """The weighted sky raster e = e_sky + e_sun (Max 1991, Fig. 6) on a sky-plane grid.

    A cell holds the integral of L cos^4(theta) dA over it.

    Parameters
    ----------
    sky : procedural.ProceduralSky
        The sky.
    grid : Grid
        The sky-plane grid (the grid an IsolatedPlan correlates) [tan].

    Returns
    -------
    e_sky : ndarray, shape (rows, cols, 3), float32
        The sky without the sun disc (``sky.raster``) [klx].
    e_sun : ndarray, shape (rows, cols, 3), float32
        The sun kernel rasterized at the same cell [klx].
    """
    e_sky = np.moveaxis(sky.raster(grid).weighted, 0, -1)
    e_sun = np.zeros_like(e_sky)
    kernel = sun_kernel(sky, grid.pixel)
    _add_at_offset(e_sun, np.moveaxis(kernel.weighted, 0, -1), kernel.grid, grid)
    return e_sky, e_sun


def log_display(values: np.ndarray, *, top: float | None = None, decades: float | None = None) -> np.ndarray:
    """Display values in [0, 1] (rows, cols, 3) of non-negative RGB ``values`` whose luminance
    spans many decades (Max 1991, Fig. 6): brightness is log10 of the luminance over the
    ``decades`` below ``top`` (None: the brightest cell; brighter cells clip to full
    brightness), by default down to the dimmest lit cell with a quarter decade to spare, used
    as the display value as it is (a log scale has no use for the sRGB curve); each pixel keeps
    its hue (its brightest channel is that brightness).

    Parameters
    ----------
    values : ndarray, shape (rows, cols, 3)
        Non-negative RGB values (any unit of light).
    top : float or None
        The luminance shown at full brightness, in the unit of ``values``; None: the brightest cell.
    decades : float or None
        Decades of luminance shown below ``top``; None: down to the dimmest lit cell, a quarter
        decade to spare.

    Returns
    -------
    ndarray, shape (rows, cols, 3), float32
        Display values in [0, 1] [1].
    """
    values = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    luminance = values @ REC709_LUMINANCE.astype(np.float64)
    top = luminance.max() if top is None else float(top)
    lit = luminance[luminance > 0]
    if not top > 0 or lit.size == 0:
        return np.zeros(values.shape, dtype=np.float32)
    if decades is None:
        decades = np.log10(top / min(lit.min(), top)) + 0.25
    with np.errstate(divide="ignore"):
        level = np.clip(1.0 + np.log10(luminance / top) / max(decades, 1e-6), 0.0, 1.0)
    peak = values.max(axis=-1, keepdims=True)
    hue = np.divide(values, peak, out=np.zeros_like(values), where=peak > 0)
    return (hue * level[..., None]).astype(np.float32)


def sky_display(radiance: np.ndarray) -> np.ndarray:
    """Display values of a sky image: the median luminance at 0.4, then ``x / (1 + x)``.

    To keep the sun and its glow from clipping flat (``composite.display_sky`` for a whole image,
    not an equirectangular upper half).

    Parameters
    ----------
    radiance : ndarray, shape (rows, cols, 3)
        The sky image [kcd/m^2].

    Returns
    -------
    ndarray, shape (rows, cols, 3)
        sRGB display values in [0, 1] [1].
    """
    radiance = np.asarray(radiance, dtype=np.float32)
    median = float(np.median(radiance @ REC709_LUMINANCE))
    exposed = radiance * np.float32(0.4 / median if median > 0 else 1.0)
    return composite.srgb_encode(exposed / (1.0 + exposed))


def i0_quadrature(alpha: ArrayLike, *, points: int = 64) -> np.ndarray:
    """I0(alpha) [sr] by quadrature over the hemisphere, independently of the closed form
    (Max 1991, error analysis and Fig. 16): the directions inside the sky square of half-angle
    alpha [rad] are, at azimuth phi, those with tan(theta) <= tan(alpha) / max(|cos phi|,
    |sin phi|), so I0 = 8 int_0^{pi/4} sin^2(theta_max(phi)) / 2 dphi (the area of the paper's
    region K), by Gauss-Legendre in phi.

    Parameters
    ----------
    alpha : float or array_like
        Half-angle of the sky square [rad].
    points : int
        Gauss-Legendre points [1].

    Returns
    -------
    ndarray
        I0, the shape of ``alpha`` [sr].
    """
    alpha = np.asarray(alpha, dtype=np.float64)
    x, w = np.polynomial.legendre.leggauss(points)
    phi = (x + 1.0) * np.pi / 8.0
    theta_max = np.arctan(np.tan(alpha)[..., None] / np.cos(phi))
    return 8.0 * (0.5 * np.sin(theta_max) ** 2 * w).sum(axis=-1) * np.pi / 8.0


def i0_plot(*, width: int = 960, height: int = 640) -> np.ndarray:
    """The plot of I0(alpha) / pi for alpha from 0 to 90 degrees (Max 1991, Fig. 16), the closed
    form ``geometry.I0`` as a curve, ``i0_quadrature`` as dots, the paper's alpha = 70 degrees
    (about 0.90) marked.

    Parameters
    ----------
    width : int
        The picture's width [pixel].
    height : int
        Its height [pixel].

    Returns
    -------
    ndarray, shape (height, width, 3)
        Display values in [0, 1] [1].
    """
    figure, axes = _figure(width, height)
    degrees = np.linspace(0.0, 90.0, 361)
    axes.plot(degrees, I0(np.radians(degrees)) / np.pi, color="tab:blue", lw=2,
              label=r"$I_0(\alpha)/\pi = 4 \sin\alpha \, \arctan(\sin\alpha) / \pi$")
    check = np.arange(5.0, 90.0, 5.0)
    axes.plot(check, i0_quadrature(np.radians(check)) / np.pi, "o", color="tab:orange", ms=5,
              label="quadrature over the hemisphere")
    at70 = float(I0(np.radians(70.0)) / np.pi)
    axes.plot([70.0, 70.0, 0.0], [0.0, at70, at70], ls="--", color="0.4", lw=1)
    axes.annotate(rf"$\alpha = 70°$: {at70:.3f} (the paper: 0.90)", (70.0, at70),
                  xytext=(22.0, 0.95), arrowprops={"arrowstyle": "->", "color": "0.3"})
    axes.set(xlim=(0, 90), ylim=(0, 1.05), xticks=np.arange(0, 91, 10),
             xlabel=r"$\alpha$, half-angle of the sky square [deg]",
             ylabel=r"$I_0(\alpha) / \pi$",
             title="Fig. 16: share of a uniform sky's irradiance inside the sky square")
    axes.grid(alpha=0.3)
    axes.legend(loc="lower right")
    return _pixels(figure)


def sun_fraction_curve(config: Config) -> tuple[list[datetime], np.ndarray, np.ndarray]:
    """The sun's fraction S and the uncovered disc area at every output frame of a site-and-time config.

    Parameters
    ----------
    config : settings.Config
        A resolved config with a site and time.

    Returns
    -------
    times : list of datetime
        UTC times.
    fraction : ndarray, shape (frames,)
        S, ``sky.sun_fraction()`` of the frame's sky (limb-darkened, luminance-weighted, clouds
        included) [1].
    area : ndarray, shape (frames,)
        1 - ``ephemeris.obscured_fraction`` (a uniform disc) [1].
    """
    times, fraction, area = [], [], []
    for frame in range(config.animation.frames):
        scene = scene_at(config, frame)
        if scene.sun is None or scene.moon is None or scene.when is None:
            raise ValueError(f"{config.path}: S(t) needs a sky with a site and time (sky.site, sky.time)")
        fraction.append(load_sky(config.sky, scene).sun_fraction())
        sun, moon = (ephemeris.BodyPosition(disc.azimuth, disc.elevation, disc.angular_radius)
                     for disc in (scene.sun, scene.moon))
        d = ephemeris.separation(sun, moon)
        area.append(1.0 - ephemeris.obscured_fraction(d, sun.angular_radius, moon.angular_radius))
        times.append(scene.when)
    return times, np.array(fraction), np.array(area)


def sun_fraction_plot(config: Config, *, title: str, width: int = 960, height: int = 640) -> np.ndarray:
    """The plot of S(t) through an eclipse, UTC time across, the contacts C1 to C4 marked.

    S: the direct sun over that of the clear, uneclipsed sun (docs/method.md, "The procedural sky").

    Parameters
    ----------
    config : settings.Config
        A resolved config with a site and time.
    title : str
        The plot's title.
    width, height : int
        The picture's size [pixel].

    Returns
    -------
    ndarray, shape (height, width, 3)
        Display values in [0, 1] [1].
    """
    import matplotlib.dates as mdates

    times, fraction, area = sun_fraction_curve(config)
    site = config.sky.site
    if site is None:
        raise ValueError(f"{config.path}: S(t) needs a sky with a site and time (sky.site, sky.time)")
    contacts = ephemeris.contact_times(ephemeris.Site(site.latitude, site.longitude, site.elevation),
                                       site.start, site.end)
    figure, axes = _figure(width, height)
    naive = [t.astimezone(UTC).replace(tzinfo=None) for t in times]
    axes.plot(naive, fraction, color="tab:orange", lw=2, label="S(t): sun after the moon (limb-darkened)")
    axes.plot(naive, area, color="0.45", lw=1, ls="--", label="uncovered area of the disc")
    for name, when in contacts.items():
        if when is not None:
            x = when.astimezone(UTC).replace(tzinfo=None)
            axes.axvline(x, color="0.6", lw=0.8, ls=":")
            align = {"C2": "right", "C3": "left"}.get(name, "center")
            axes.text(x, 1.02, f" {name} ", ha=align, va="bottom", fontsize=9, color="0.3")
    axes.xaxis.set_major_formatter(mdates.DateFormatter("%H:%M"))
    axes.set(ylim=(-0.02, 1.1), xlim=(naive[0], naive[-1]), xlabel="time [UTC]", ylabel="S [1]")
    axes.set_title(title, pad=18)
    axes.grid(alpha=0.3)
    axes.legend(loc="lower right")
    return _pixels(figure)


def _figure(width: int, height: int, dpi: int = 120):
    """A matplotlib Figure of ``width`` x ``height`` pixels with one Axes, on its own Agg canvas
    (no pyplot, no backend switch)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.add_subplot()


def _pixels(figure) -> np.ndarray:
    """The drawn Figure as display values (rows, cols, 3) in [0, 1] (exact 8-bit codes)."""
    figure.canvas.draw()
    rgba = np.asarray(figure.canvas.buffer_rgba())
    return rgba[..., :3].astype(np.float32) / 255.0


# ---------------------------------------------------------------------------------------------
# The set
# ---------------------------------------------------------------------------------------------


@dataclass
class _Scenes:
    """The scenes and renders the figures share, each made once, when first asked for."""

    store: cache.Cache
    preview: bool
    _configs: dict[str, Config] = field(default_factory=dict)

    def config(self, name: str) -> Config:
        if name not in self._configs:
            self._configs[name] = scene_config(name, preview=self.preview)
        return self._configs[name]

    @cached_property
    def grove_plan(self) -> RunPlan:
        return plan_run(self.config("grove"))

    @cached_property
    def grove_sky(self) -> procedural.ProceduralSky:
        sky = self.grove_plan.sky.at(self.grove_plan.scenes[0])
        if not isinstance(sky, procedural.ProceduralSky):  # the grove's sky is a CIE sky
            raise TypeError(f"the grove's sky is a {type(sky).__name__}, not a procedural sky")
        return sky

    @cached_property
    def grove_frame(self) -> FrameResult:
        return render_frame(self.grove_plan, 0, store=self.store)

    @cached_property
    def eclipse_frame(self) -> FrameResult:
        config = self.config("crescents")
        return render_frame(plan_run(config), config.animation.frames - 1, store=self.store)


def _fig_mask(scenes: _Scenes) -> np.ndarray:
    """Fig. 4: the grove's upper layer's coarse mask at cycle frame 0, grey."""
    return layer_masks(scenes.grove_plan, 0, 0).coarse[..., None]


def _fig_sky(scenes: _Scenes) -> np.ndarray:
    """Fig. 5: the grove's sky on the sky plane."""
    size = 256 if scenes.preview else 1024
    image = sky_plane_image(scenes.grove_sky, alpha=scenes.config("grove").sky.alpha, size=size)
    return sky_display(image)


def _fig_sky_raster(scenes: _Scenes) -> np.ndarray:
    """Fig. 6: the weighted raster of the grove's upper layer, log scale from the brightest sky
    cell (the sun, far brighter, is white) down to the dimmest."""
    grid = scenes.grove_plan.layers[0].coarse.sky
    if grid is None:  # the grove's canopy is within the sky square's reach
        raise ValueError("no sky offset of the grove's upper layer reaches its canopy")
    e_sky, e_sun = weighted_sky_raster(scenes.grove_sky, grid)
    brightest = float((e_sky @ REC709_LUMINANCE).max())
    return log_display(e_sky + e_sun, top=brightest)


def _fig_ground(scenes: _Scenes) -> np.ndarray:
    """Fig. 7: the grove's whole ground window (the coarse raster with the sun at the coarse
    cell, the paper's single scale), or the two-scale raster where the sun window covers it."""
    ground = scenes.grove_frame.ground
    raster = ground.outer.irradiance if ground.outer is not None else ground.irradiance
    return composite.display_ground(raster, ground.unshadowed)


def _fig_frame(scenes: _Scenes) -> np.ndarray:
    """Fig. 10: the grove's finished frame 0."""
    result = scenes.grove_frame
    return composite.display(result.radiance, exposure=result.exposure, balance=result.balance,
                             transform=scenes.config("grove").camera.display)


def _fig_point_sun(scenes: _Scenes) -> np.ndarray:
    """Fig. 11: the grove's frame 0 under a point sun, no sky light."""
    config = scenes.config("point-sun")
    result = render_frame(plan_run(config), 0, store=scenes.store)
    return composite.display(result.radiance, exposure=result.exposure, balance=result.balance,
                             transform=config.camera.display)


def _fig_eclipse_ground(scenes: _Scenes) -> np.ndarray:
    """Fig. 12: the two-scale ground raster of the eclipse's last frame over the sun window."""
    ground = scenes.eclipse_frame.ground
    return composite.display_ground(ground.irradiance, ground.unshadowed)


def _fig_eclipse_frame(scenes: _Scenes) -> np.ndarray:
    """Fig. 13: the eclipse's last frame."""
    result = scenes.eclipse_frame
    return composite.display(result.radiance, exposure=result.exposure, balance=result.balance,
                             transform=scenes.config("crescents").camera.display)


def _fig_i0(scenes: _Scenes) -> np.ndarray:
    """Fig. 16: I0(alpha) / pi, closed form and quadrature."""
    return i0_plot()


def _fig_sun_fraction(scenes: _Scenes) -> np.ndarray:
    """S(t) of the 2024 eclipse at Dallas."""
    return sun_fraction_plot(scenes.config("dallas-2024"),
                             title="S(t): the total solar eclipse of 2024 April 8 from Dallas")


def _fig_brdf_lawn(scenes: _Scenes) -> np.ndarray:
    """The lawn scene's frame 0 with Lambert's law, with its BRDF (grass) and with the sand
    preset, side by side, all at the Lambertian frame's exposure and white balance."""
    config = scenes.config("lawn")
    lambert = replace(config, ground=replace(config.ground, brdf=None))
    model, parameters = BRDF_PRESETS["sand"]
    sand = replace(config, ground=replace(config.ground, brdf=BrdfConfig(model, tuple(parameters.items()), "sand")))
    results = [render_frame(plan_run(c), 0, store=scenes.store) for c in (lambert, config, sand)]
    shown = [composite.display(r.radiance, exposure=results[0].exposure, balance=results[0].balance,
                               transform=config.camera.display) for r in results]
    gap = np.ones((shown[0].shape[0], max(2, shown[0].shape[1] // 100), shown[0].shape[2]), dtype=shown[0].dtype)
    return np.concatenate([shown[0], gap, shown[1], gap, shown[2]], axis=1)


_MAKERS = {
    "fig04-mask.png": _fig_mask,
    "fig05-sky.png": _fig_sky,
    "fig06-sky-raster.png": _fig_sky_raster,
    "fig07-ground.png": _fig_ground,
    "fig10-frame.png": _fig_frame,
    "fig11-point-sun.png": _fig_point_sun,
    "fig12-eclipse-ground.png": _fig_eclipse_ground,
    "fig13-eclipse-frame.png": _fig_eclipse_frame,
    "fig16-i0.png": _fig_i0,
    "sun-fraction.png": _fig_sun_fraction,
    "brdf-lawn.png": _fig_brdf_lawn,
}


def write_figures(folder: Path, *, store: cache.Cache, preview: bool = False,
                  progress: Callable[[str, int, int], None] | None = None) -> list[Path]:
    """Write every PNG of FIGURES into ``folder``, in order, each atomically (``io.write_png``).

    Prints nothing.

    Parameters
    ----------
    folder : pathlib.Path
        Where; it must exist.
    store : store.Cache
        Holds the cycle products (masks' spectra, foreground passes) the renders share.
    preview : bool
        Make the scenes small (seconds, not minutes).
    progress : callable or None
        ``progress(name, done, total)``, called after each figure.

    Returns
    -------
    list of pathlib.Path
        The figures' paths.
    """
    folder = Path(folder)
    scenes = _Scenes(store, preview)
    written = []
    for done, (name, _caption) in enumerate(FIGURES, start=1):
        path = folder / name
        io.write_png(path, _MAKERS[name](scenes))
        written.append(path)
        if progress is not None:
            progress(name, done, len(FIGURES))
    return written


__all__ = ["FIGURES", "SCENES", "PREVIEW", "scene_config", "write_figures", "sky_plane_image",
           "weighted_sky_raster", "log_display", "sky_display", "i0_quadrature", "i0_plot",
           "sun_fraction_curve", "sun_fraction_plot"]
