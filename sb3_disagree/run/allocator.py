"""The C allocator's settings for training: freed memory is kept for reuse instead of handed back to the OS."""

import ctypes
import ctypes.util
import sys

# glibc's mallopt parameters (malloc.h)
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
MMAP_THRESHOLD = 256 << 20  # blocks up to this size come from the heap, not from a fresh mapping each time
TRIM_THRESHOLD = 1 << 30  # free memory at the heap's top kept up to this size
TOP_PAD = 256 << 20  # the heap grows by at least this much at a time (address space; pages on first use)

_done = False


def keep_freed_memory() -> bool:
    """
    Keep freed memory in the process for reuse (glibc only; elsewhere nothing changes).

    A training step allocates and frees arrays and tensors of a few MB (replay segments of stacked frames, the
    CNN's activations). glibc's defaults serve such blocks from fresh mappings, or hand the heap's top back to
    the OS, so each step page-faults its memory in again: about 3 million minor page faults in 14k env steps of
    ``dopt train``, against 0.2 million with these settings, and 14% more env steps/s (docs/benchmarks.md,
    "The allocator"). The process keeps at most ``TRIM_THRESHOLD`` of free memory at its heap's top.

    :return: Whether the settings were applied (once per process; False where the C library has no mallopt)
    """
    global _done
    if _done:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # another C library (musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    _done = all(mallopt(param, value) == 1 for param, value in
                ((M_MMAP_THRESHOLD, MMAP_THRESHOLD), (M_TRIM_THRESHOLD, TRIM_THRESHOLD), (M_TOP_PAD, TOP_PAD)))
    return _done
