"""The foreground: the trees rendered as the camera sees them, their detail, passes as data and the
foreground models a config may name.

May import: core, kernels, config, canopy, camera."""
