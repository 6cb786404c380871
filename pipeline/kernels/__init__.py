"""The compiled loops (numba): whole-array expressions, the camera's filtered reads, the rasteriser's
coverage and the hashed tilings; each called by the module of another package that it serves.

May import: core."""

from typing import Any

__all__ = ["LOOP", "HELPER"]

LOOP: dict[str, Any] = {"no_cfunc_wrapper": True}
"""``njit``'s options of a loop called from Python: without numba's C-callable wrapper (nothing takes a
loop's address), only more LLVM to build and optimise (docs/accuracy.md, "Compiling after an install").
A dict, as numba's stubs lack the keyword."""

HELPER: dict[str, Any] = {"no_cfunc_wrapper": True, "no_cpython_wrapper": True}
"""``njit``'s options of a helper that only other loops call: without its Python wrapper either. Helpers
inlined (``inline="always"``) are never compiled on their own and need neither."""
