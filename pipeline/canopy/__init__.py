"""The canopy: mask images, the procedural grove and its flutter, the anti-aliased rasteriser.

May import: core, kernels."""
