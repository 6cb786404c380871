"""The camera: the pinhole's rays and projection, the ground with its reflectance as seen, and the
compositor of the finished frame.

May import: core, kernels, config, sky, ground, texture."""
