"""The stages of a run in order: resolve and plan (the only readers of the config), the scene, the
framing, the lighting, the inputs, then the cycle, ground and frame stages.

May import: every other package but run and cli."""
