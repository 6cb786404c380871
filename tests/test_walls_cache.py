"""The walls' cycle products (``stages.wall_cycle``): made in the cycle phase and read back, they
give the bytes of the wall drawn for the frame alone; their key follows the mask files; and a
pergola's trellis bar throws its shadow where the sun's rays through its edges meet the wall
(docs/method.md, "Receivers: walls and slopes")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from scenes import plan_of, tiny_grove

from pipeline.cache import keys as cache_keys
from pipeline.cache import store as cache
from pipeline.core import io
from pipeline.stages.cycle import config_item_keys, cycle_phase
from pipeline.stages.ground import FrameContext
from pipeline.stages.wall_cycle import WALL_KIND, wall_params
from pipeline.stages.walls import wall_of_frame

ROOT = Path(__file__).resolve().parents[1]


def bar_mask(folder: Path, name: str = "bar.png", *, rows=(9, 11), cols=None) -> Path:
    """A 20 x 20 mask, open but for rows (or columns) ``[a, b)`` of wood [1]."""
    image = np.ones((20, 20), np.float32)
    if cols is None:
        image[rows[0]:rows[1], :] = 0.0
    else:
        image[:, cols[0]:cols[1]] = 0.0
    io.write_png(folder / name, image[..., None])
    return folder / name


def wall_config(folder: Path) -> dict:
    """tiny_grove with a wall 2 m east of its tree facing west, behind a bar mask, a small camera."""
    bar_mask(folder)
    config = tiny_grove()
    config["camera"] = {"position": [-3.0, -2.0, 1.5], "look_at": [2.0, 0.0, 1.0], "resolution": [96, 64]}
    config["foreground"] = {"model": "none"}  # no trees' passes: the wall's and the ground's products alone
    config["receivers"] = {"walls": [{"foot": [2.0, 0.0], "facing": 270.0, "width": 3.0, "height": 2.0,
                                      "pixel": 0.05, "masks": [{"image": "bar.png", "center": [0.0, 1.2],
                                                                "size": [1.0, 1.0], "distance": 0.3}]}]}
    return config


def test_the_cycle_phase_stores_the_walls_products_and_the_frames_read_them_to_the_bit(tmp_path):
    """Every cycle frame's wall item is made in the cycle phase (a second phase makes none); the
    wall's raster read from them is the bytes of the wall drawn for that frame alone
    (``wall_light``), the frame's only input from the wall; and a frame without its item makes it."""
    from pipeline.receivers.walls import wall_light
    from pipeline.stages.inputs import albedo_mipmap, grove_of
    from pipeline.stages.walls import _open_ground

    plan = plan_of(wall_config(tmp_path), tmp_path)
    store = cache.Cache(tmp_path / "cache")
    kinds = [kind for kind, _ in config_item_keys(plan).values()]
    assert kinds.count(WALL_KIND) == plan.canopy.cycle
    assert cycle_phase(plan, store) == len(kinds) == 2 * plan.canopy.cycle  # the canopy layer's and the wall's
    assert cycle_phase(plan, store) == 0
    for frame in (2, 1):
        cached = wall_of_frame(plan, frame, "wall0", store=store, workers=1).irradiance
        context = FrameContext.of(plan, frame, store=store, workers=1)
        alone = wall_light(plan.receivers.walls[0], context.sky, ground_albedo=albedo_mipmap(plan.ground).mean,
                           open_ground=_open_ground(context.sky), grove=grove_of(plan.canopy),
                           cycle_frame=context.cycle_frame, workers=1)
        assert cached.tobytes() == alone.irradiance.tobytes()
    empty = cache.Cache(tmp_path / "empty")  # a frame makes its missing products and reads them again
    assert wall_of_frame(plan, 1, "wall0", store=empty, workers=1).irradiance.tobytes() == cached.tobytes()
    assert cycle_phase(plan, empty) == len(kinds) - 1  # frame 1's wall item was made


def test_a_changed_mask_file_changes_the_walls_key(tmp_path):
    """The key holds the mask file's bytes: the same bytes written again keep it, others change it."""
    plan = plan_of(wall_config(tmp_path), tmp_path)
    key = cache_keys.key_of(WALL_KIND, wall_params(plan, 0, 0))
    bar_mask(tmp_path)  # the same bytes, written again
    assert cache_keys.key_of(WALL_KIND, wall_params(plan, 0, 0)) == key
    bar_mask(tmp_path, rows=(5, 8))
    assert cache_keys.key_of(WALL_KIND, wall_params(plan, 0, 0)) != key
    changed = cache_keys.key_of(WALL_KIND, wall_params(plan, 0, 0))
    assert cache_keys.key_of(WALL_KIND, wall_params(plan, 0, 1)) != changed  # each cycle frame its own


def test_trees_moved_in_front_of_a_wall_change_its_key(tmp_path):
    """The trees stand around the canopy's centre (``inputs.grove_of``): moving it moves their
    shadow on the wall, so the wall's key changes with it (through the wall's run plan, whose
    layers' distances and windows follow the trees)."""
    config = wall_config(tmp_path)
    key = cache_keys.key_of(WALL_KIND, wall_params(plan_of(config, tmp_path), 0, 0))
    config["canopy"]["center"] = [-0.3, 0.2]
    assert cache_keys.key_of(WALL_KIND, wall_params(plan_of(config, tmp_path), 0, 0)) != key


def shadow_edges(profile: np.ndarray, places: np.ndarray, near: float) -> tuple[float, float]:
    """The two places [m] within 0.25 m of ``near`` where ``profile`` (at ``places``, increasing)
    crosses halfway between its lit level and its darkest there, linearly between cells."""
    keep = np.abs(places - near) < 0.25
    profile, places = profile[keep], places[keep]
    half = (np.max(profile) + np.min(profile)) / 2
    below = np.flatnonzero(profile < half)
    first, last = below[0], below[-1]

    def cross(i, j):  # between cells i and j, one each side of half
        t = (profile[i] - half) / (profile[i] - profile[j])
        return places[i] + t * (places[j] - places[i])

    return cross(first - 1, first), cross(last, last + 1)


def test_a_pergola_trellis_bars_shadow_lies_where_the_suns_rays_through_its_edges_meet_the_wall(tmp_path):
    """configs/pergola.yaml's wall and sun (its first frame) with the trellis cut to one horizontal
    and one vertical bar: the bars' shadow edges on the wall's raster lie where the sun's rays
    through the bars' edges meet the wall, within a pixel (1 cm)."""
    from pipeline.receivers.sun import receiver_sun_point
    from pipeline.receivers.walls import wall_plane

    config = yaml.safe_load((ROOT / "configs" / "pergola.yaml").read_text())
    config["canopy"]["mask"] = str(ROOT / "configs" / "assets" / "lattice.png")
    config["ground"]["albedo"] = str(ROOT / "configs" / "assets" / "sand.png")
    config["animation"]["frames"] = 1
    wall = config["receivers"]["walls"][0]
    wall.update(width=3.0, height=3.2)
    trellis = wall["masks"][0]
    bar_mask(tmp_path, "h.png", rows=(8, 10))  # w from 1.6 down to 1.5 m: 2.0 - 0.05 x (8, 10)
    bar_mask(tmp_path, "v.png", cols=(13, 15))  # u from 0.15 to 0.25 m: -0.5 + 0.05 x (13, 15)
    wall["masks"] = [{**trellis, "image": "h.png", "center": [0.0, 1.5], "size": [1.0, 1.0]},
                     {**trellis, "image": "v.png", "center": [0.0, 1.5], "size": [1.0, 1.0]}]
    plan = plan_of(config, tmp_path)
    light = wall_of_frame(plan, 0, "house", store=cache.Cache(tmp_path / "cache"), workers=1)
    sky = plan.sky.at(plan.scenes[0])
    su, sw = receiver_sun_point(sky, wall_plane(plan.receivers.walls[0]))
    d = trellis["distance"]
    assert sw > 1.0  # the high sun throws the bar's shadow well below it, clear of its sky shade
    y = light.irradiance @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    grid = light.grid
    u0, w0 = grid.origin
    us = u0 + grid.pixel * (np.arange(grid.shape[1]) + 0.5)
    ws = w0 - grid.pixel * (np.arange(grid.shape[0]) + 0.5)
    column = int((-0.3 - d * su - u0) / grid.pixel)  # away from the vertical bar's shadow
    low, high = shadow_edges(y[::-1, column], ws[::-1], 1.55 - d * sw)
    assert abs(low - (1.5 - d * sw)) < grid.pixel and abs(high - (1.6 - d * sw)) < grid.pixel
    row = int((w0 - (1.9 - d * sw)) / grid.pixel)  # above the horizontal bar's shadow
    left, right = shadow_edges(y[row], us, 0.2 - d * su)
    assert abs(left - (0.15 - d * su)) < grid.pixel and abs(right - (0.25 - d * su)) < grid.pixel
