"""A run: frames rendered into a folder resumably, its index, its record (run.json) and its report.

May import: every other package but cli."""
