"""Whether the matcher's compiled kernels are in numba's on-disk cache yet (a fresh install)."""

from __future__ import annotations

import os

__all__ = ["kernels_on_disk"]


def kernels_on_disk() -> bool:
    """
    Whether the two largest stage kernels have an entry in numba's on-disk cache.

    On a fresh install they have none, and the first match compiles every kernel (about a
    minute); ``mapmatch network build`` does that ahead. Any doubt (numba's cache object not
    where this looks for it) answers True, so that the caller stays quiet.
    """
    from mapmatch.hmm.assemble import _assemble_kernel
    from mapmatch.hmm.trellis import solve_kernel

    kernels: tuple[object, ...] = (_assemble_kernel, solve_kernel)
    try:  # numba's private cache object: on disk beside the source, or NUMBA_CACHE_DIR
        paths = [k._cache._cache_file._index_path for k in kernels]  # type: ignore[attr-defined]
    except AttributeError:  # another numba version keeps it elsewhere
        return True
    return all(os.path.exists(p) for p in paths)
