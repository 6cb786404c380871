"""The ``sunshade`` command: its parser, the commands over runs and pictures, shared flags, the
paper's figures.

May import: anything."""
