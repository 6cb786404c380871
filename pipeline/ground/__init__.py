"""The ground's light: the correlation of the sky with the canopy masks (Max 1991), the reflectance
and the sky's term of it through view bands.

May import: core, kernels, config, sky."""
