"""The compiled loops (numba): whole-array expressions, the camera's filtered reads, the rasteriser's
coverage and the hashed tilings; each called by the module of another package that it serves.

May import: core."""
