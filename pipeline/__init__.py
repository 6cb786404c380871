"""sunshade: sunlight and skylight through leaves, after Nelson Max (1991)."""

__version__ = "0.1.0"
