"""numba's ``njit``, or a stand-in that leaves functions as plain Python when numba is missing."""
from __future__ import annotations

try:  # numba is a declared dependency; the fallback keeps the code importable.
    from numba import njit
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

    def njit(*a, **k):  # type: ignore[no-redef]
        """Return the function unchanged (with ``py_func`` pointing at itself)."""
        def deco(f):
            f.py_func = f
            return f
        return deco if not (a and callable(a[0])) else deco(a[0])

__all__ = ["njit", "HAVE_NUMBA"]
