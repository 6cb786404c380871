"""The names and ranges a config may give: one home for the parser (``config``) and for the
models that act on them. Plain values and no imports, so that ``config`` reads them without
importing a physics module."""

PROCEDURAL_MODELS = ("cie", "preetham")
"""The procedural sky's models (sky.model), named by the clear sky's angular shape."""

SKY_MODELS = (*PROCEDURAL_MODELS, "uniform", "hdri")
"""Every sky model a config may name (sky.model); 'procedural' is read as 'cie'."""

CIE_TYPE_RANGE = (1, 15)
"""The CIE standard general skies (ISO 15469:2004), numbered from first to last."""

DEFAULT_CIE_TYPE = 12
"""The clear sky drawn when a config names no type: CIE type 12, the standard clear sky of low
illuminance turbidity (docs/accuracy.md, "Daylight: the clear sky in absolute units", says how it
was chosen)."""

TURBIDITY_RANGE = (1.5, 10.0)
"""Linke turbidity factors accepted: the climatology's values lie within (about 1.8 to 7), and
the sky's colour model (Preetham et al. 1999) needs more than 1.2. [1]"""

DISPLAYS = ("srgb", "filmic")
"""Display transforms from exposed scene-linear values to sRGB code values."""

WHITE_BALANCES = ("daylight", "shade", "none")
"""What a picture shows as white, as a camera's white balance: ``daylight`` the open ground's
light (sun and sky), ``shade`` the sky's light alone (the shade under trees comes out neutral and
the sun flecks warm, as in photographs taken in the shade), ``none`` linear Rec.709's D65 white."""

PASSES = ("sun", "sky", "alpha", "illuminance", "depth")
"""The light passes a frame's EXR may hold beside its beauty (output.passes; docs/runs.md,
"Light passes"): ``sun`` and ``sky`` the frame's light from the sun and from the sky (RGB, they
sum to the beauty), ``alpha`` the foreground's coverage, ``illuminance`` the ground's horizontal
illuminance [lux], ``depth`` the distance to the ground seen [m]."""
