"""The sky: the procedural sky and its models, daylight in absolute units, twilight, the ephemeris,
the eclipse, the sun and moon discs, the sun's kernel, HDRI skies, clouds and their scattering.

May import: core, kernels, config."""
