"""The names and ranges a config may give: one home for the parser (``parse``) and for the
models that act on them. Plain values and the model registries, which import their models only
when asked for one, so that the config package reads them without importing a physics module."""

from pipeline.config.registry import Model, Registry

__all__ = ["PROCEDURAL_MODELS", "SKIES", "SKY_MODELS", "FOREGROUNDS",
           "CIE_TYPE_RANGE", "DEFAULT_CIE_TYPE", "TURBIDITY_RANGE", "DISPLAYS",
           "WHITE_BALANCES", "FOLLOWS", "SEED_MAX", "NUMBER_RANGES", "TIME_RANGE", "PASSES", "BRDF_PARAMETERS",
           "REFLECTANCES", "BRDF_PRESETS", "BRDF_CHANNELS"]

PROCEDURAL_MODELS = ("cie", "preetham")
"""The procedural sky's models (sky.model), named by the clear sky's angular shape."""

_PROCEDURAL_KEYS = ("turbidity", "sun", "site", "time", "moon", "clouds", "skylight")

SKIES = Registry(
    "sky.model",
    Model("cie", "sky.models:ProceduralModel", ("cie_type", *_PROCEDURAL_KEYS)),
    Model("preetham", "sky.models:ProceduralModel", _PROCEDURAL_KEYS),
    Model("uniform", "sky.models:UniformModel", ("radiance",)),
    Model("hdri", "sky.models:HdriModel", ("hdri", "rotation")),
    Model("overcast", "sky.overcast:OvercastModel", numbers={"luminance": (1.0, 0.0, 1e30, "kcd/m^2")}),
)
"""Every sky model a config may name (sky.model; 'procedural' is read as 'cie'), the keys of
``sky`` that only it takes and its class (``sky.models.SkyModel``; docs/design.md, "Models plug in")."""

SKY_MODELS = SKIES.names

FOREGROUNDS = Registry(
    "foreground.model",
    Model("trees", "foreground.models:TreesForeground"),
    Model("passes", "foreground.models:ImportedForeground", ("sun", "sky", "alpha")),
    Model("none", "foreground.models:NoForeground"),
)
"""The foreground models (foreground.model): the built-in trees, passes read from files, none
(``foreground.models.ForegroundModel``)."""

CIE_TYPE_RANGE = (1, 15)
"""The CIE standard general skies (ISO 15469:2004), numbered from first to last. [1]"""

DEFAULT_CIE_TYPE = 12
"""The clear sky drawn when a config names no type: CIE type 12, the standard clear sky of low
illuminance turbidity (docs/accuracy.md, "Daylight: the clear sky in absolute units", says how it
was chosen). [1]"""

TURBIDITY_RANGE = (1.5, 10.0)
"""Linke turbidity factors accepted: the climatology's values lie within (about 1.8 to 7), and
the sky's colour model (Preetham et al. 1999) needs more than 1.2. [1]"""

DISPLAYS = ("srgb", "filmic")
"""Display transforms from exposed scene-linear values to sRGB code values."""

WHITE_BALANCES = ("daylight", "shade", "none")
"""What a picture shows as white, as a camera's white balance: ``daylight`` the open ground's
light (sun and sky), ``shade`` the sky's light alone (the shade under trees comes out neutral and
the sun flecks warm, as in photographs taken in the shade), ``none`` linear Rec.709's D65 white."""

FOLLOWS = ("auto", "shadow", "fixed")
"""How a camera the plan places moves over the frames (``camera.follow``, docs/method.md,
"Framing"): ``shadow`` pans with the canopy's shadow, ``fixed`` stays where the middle frame puts
it, ``auto`` pans when the shadow would stray from a fixed camera's view."""

SEED_MAX = 2**63 - 1
"""Largest random seed (trees, clouds): the compiled hashes take a signed 64-bit integer. [1]"""

NUMBER_RANGES = {
    "animation.fps": (0.01, 1000.0, "frames per second"),
    "ground.window": (-1e5, 1e5, "m"),
    "ground.sun_window": (-1e5, 1e5, "m"),
    "ground.pixel": (0.0, 100.0, "m"),
    "ground.albedo_size": (0.01, 1e4, "m"),
    "canopy.size": (0.0, 1e5, "m"),
    "canopy.center": (-1e5, 1e5, "m"),
    "canopy.height": (0.01, 1000.0, "m"),
    "canopy.layers[].size": (0.0, 1e5, "m"),
    "canopy.layers[].center": (-1e5, 1e5, "m"),
    "canopy.layers[].height": (0.01, 1000.0, "m"),
    "canopy.trees.count": (1, 1000, "trees"),
    "canopy.trees.seed": (0, SEED_MAX, ""),
    **{f"canopy.{mesh}.{key}": limits for mesh in ("mesh", "mesh[]") for key, limits in (
        ("seed", (0, SEED_MAX, "")), ("scale", (1e-6, 1e6, "m per file unit")), ("position", (-1e4, 1e4, "m")),
        ("rotation", (-360.0, 360.0, "deg")))},
    "canopy.trees.crown_radius": (0.0, 100.0, "m"),
    "canopy.trees.leaf_length": (0.001, 10.0, "m"),
    "canopy.trees.spread": (0.0, 1e4, "m"),
    "canopy.flutter.cycle": (1, 100_000, "frames"),
    "sky.moon.offset_start": (-90.0, 90.0, "degrees"),
    "sky.moon.offset_end": (-90.0, 90.0, "degrees"),
    "sky.clouds.scale": (1.0, 1e6, "m"),
    "sky.clouds.altitude": (1.0, 1e5, "m"),
    "sky.clouds.wind": (-300.0, 300.0, "m/s"),
    "sky.clouds.thickness": (0.0, 1000.0, ""),
    "sky.clouds.seed": (0, SEED_MAX, ""),
    "sky.haze": (0.0, 1e9, "m"),
    "camera.position": (-1e5, 1e5, "m"),
    "camera.look_at": (-1e5, 1e5, "m"),
    "camera.fov": (0.01, 170.0, "degrees"),
}
"""The range [least, most] and unit of every number a config may give that the code cannot
compute with at any size (a layer's key written ``layers[]``): lengths, speeds, rates and counts
that overflow a raster, a time or a hash past them. The parser refuses a number outside its
range, naming the key and the range (docs/runs.md, "Errors"); the other bounds a key has
(above 0, below 90 degrees) are checked with it."""

TIME_RANGE = ("0001-01-02T00:00:00+00:00", "9999-12-30T23:59:59+00:00")
"""The first and last UTC times a config may give (sky.time), its offset applied: a day inside
the calendar that Python's dates can hold, so that the searches about a time stay in it."""

PASSES = ("sun", "sky", "alpha", "illuminance", "depth")
"""The light passes a frame's EXR may hold beside its beauty (output.passes; docs/runs.md,
"Light passes"): ``sun`` and ``sky`` the frame's light from the sun and from the sky (RGB, they
sum to the beauty), ``alpha`` the foreground's coverage, ``illuminance`` the ground's horizontal
illuminance [lux], ``depth`` the distance to the ground seen [m]."""

BRDF_PARAMETERS = {
    "lambert": {},
    "rpv": {"rho0": (0.0, 1.0, "(]"), "k": (0.0, 2.0, "()"), "theta": (-1.0, 1.0, "()"),
            "rho_c": (0.0, 1.0, "(]")},
    "rossli": {"f_iso": (0.0, 1.0, "(]"), "f_vol": (0.0, 1.0, "[]"), "f_geo": (0.0, 1.0, "[]")},
}
"""The ground's reflectance models (ground.brdf.model) and each one's parameters with their physical
ranges (least, most, brackets: "(" open, "[" closed) (docs/method.md, "The ground's
reflectance"): ``lambert`` the paper's constant; ``rpv`` Rahman, Pinty and Verstraete (1993),
rho0 the amplitude, k the Minnaert bowl (k < 1) or bell (k > 1), theta the Henyey-Greenstein
asymmetry (negative: backward scattering), rho_c the hot spot (default rho0); ``rossli``
the MODIS RossThick-LiSparse-Reciprocal kernels' weights (Lucht, Schaaf and Strahler 2000)."""

REFLECTANCES = Registry(
    "ground.brdf.model",
    *(Model(name, f"ground.brdf:{home}", tuple(BRDF_PARAMETERS[name]))
      for name, home in (("lambert", "Lambert"), ("rpv", "Rpv"), ("rossli", "RossLi"))),
)
"""The ground's reflectance models (``brdf.Reflectance``), each with its parameters."""

BRDF_PRESETS = {
    "grass": ("rpv", {"rho0": 0.014, "k": 0.810, "theta": -0.169, "rho_c": 0.014}),
    "soil": ("rpv", {"rho0": 0.147, "k": 0.839, "theta": -0.096, "rho_c": 0.147}),
    "sand": ("rpv", {"rho0": 0.29857, "k": 0.82656, "theta": 0.02074, "rho_c": 0.56090}),
}
"""Named ground reflectances a config may give as ``ground.brdf: NAME`` (docs/method.md, "The
ground's reflectance"): ``grass`` and ``soil`` Rahman, Pinty and Verstraete's (1993) fits for
grasses (rho0 = rho_c 0.014, Theta -0.169, k 0.810) and for loam soil (rho0 = rho_c 0.147,
Theta -0.096, k 0.839) in the visible band, their table as reprinted in the SHARM manual
(Lyapustin 2005); ``sand`` the desert sand of the Libya-4 site, Bouvet's spectral RPV model
(Bouvet 2014, Remote Sens. Environ. 140, 141-154; the table ESA's DIMITRI code fed to
libRadtran) reduced to luminance Y (CIE 1931 2-degree observer under D65) and refitted
(``BRDF_CHANNELS``, docs/accuracy.md, "sand: the Libya-4 fit"). The renderer applies one
shape to every channel (the albedo texture gives the colour), so a preset is one set."""

BRDF_CHANNELS = {
    "sand": {
        "r": {"rho0": 0.46052, "k": 0.89185, "theta": -0.00349, "rho_c": 0.81581},
        "g": {"rho0": 0.26849, "k": 0.80267, "theta": 0.02866, "rho_c": 0.46502},
        "b": {"rho0": 0.13474, "k": 0.76816, "theta": 0.05820, "rho_c": 0.21498},
    },
}
"""A spectral preset's RPV parameters per channel of linear Rec.709 (D65 white): Bouvet's (2014)
Libya-4 model at 390-780 nm, its BRF weighted by D65 times each primary's matching function
(the CIE 1931 2-degree observer through the Rec.709 matrix) and refitted, within 0.5% of that
weighted BRF at zeniths to 75 degrees (docs/accuracy.md, "sand: the Libya-4 fit"; the preset
itself, ``BRDF_PRESETS``, is the same reduction to Y). Recorded for a renderer with a shape per
channel; the present one reads ``BRDF_PRESETS`` only. [1]"""
