"""The foundation every stage stands on: geometry and the sky-plane mapping, physical and colour
constants, the one-line errors, paths, cores, kept views and image I/O.

Imports nothing else of pipeline."""
