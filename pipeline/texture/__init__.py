"""Texture filtering of planar rasters (the mip map and the anisotropic footprint filter) and the
procedural ground albedo.

May import: core, kernels."""
