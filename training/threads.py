"""Thread caps for the training process.

On a shared 2-core machine multi-threaded BLAS pools spin-wait against other processes:
a (16 x 201) @ (201 x 256) product took 300 us with numpy's default OpenBLAS pool and 37 us
with one thread, and PyTorch updates ran up to 100x slower with 2 threads. The training
loop therefore runs torch and numpy's BLAS on one thread each (``torch_threads`` raises
torch's count on a quiet machine).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np
import torch

_SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
            "openblas_set_num_threads64_", "openblas_set_num_threads")


def limit_threads(torch_threads: int = 1) -> bool:
    """Set torch's intra-op threads and cap numpy's OpenBLAS pool at one thread (also
    exported as ``OPENBLAS_NUM_THREADS`` for processes started later). Returns whether
    numpy's bundled OpenBLAS was found and capped."""
    torch.set_num_threads(torch_threads)
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    libs = Path(np.__file__).resolve().parent.parent / "numpy.libs"
    for lib in sorted(libs.glob("*openblas*")):
        handle = ctypes.CDLL(str(lib))
        for name in _SETTERS:
            setter = getattr(handle, name, None)
            if setter is not None:
                setter(ctypes.c_int(1))
                return True
    return False
