"""Receivers other than the level ground: walls and slopes, each lit by Max's correlation in its
own frame (docs/method.md, "Receivers: walls and slopes").

May import: core, kernels, config, sky, canopy, ground."""
