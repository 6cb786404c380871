"""The config layer: YAML read safely, parsed key by key into frozen settings, the vocabulary and the
model registries, the preview. No physics, no numpy.

May import: core."""
