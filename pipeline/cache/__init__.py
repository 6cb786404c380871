"""The cache on disk: item keys, atomically written checksummed items, the store with its budget.

May import: core."""
