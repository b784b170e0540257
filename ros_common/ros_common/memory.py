"""The C allocator's settings for processes that take large messages.

A 640x480 rgb8 image is about 0.9 MB. glibc serves a block that large with its own mmap and
unmaps it on free; a heap top that grows past the trim threshold is handed back the same way.
A node taking a stream of such messages then pays a page fault for every 4 KiB page of every
message, and the kernel zeroes each page first. In the recorder this doubled the CPU per frame
and halved its throughput, depending on where glibc's adaptive threshold happened to stand
(``bench/bench_recorder.py``).

Fixed thresholds keep blocks of up to 32 MiB on the heap and keep up to 256 MiB of freed heap
for reuse: the pages of one message serve the next.
"""
from __future__ import annotations

import ctypes
import ctypes.util

# From glibc's malloc.h.
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

MMAP_THRESHOLD = 32 * 1024 * 1024
TRIM_THRESHOLD = 256 * 1024 * 1024


def keep_large_blocks() -> bool:
    """Apply the thresholds to this process. False where the C library has no ``mallopt``
    (not glibc), which changes nothing else."""
    name = ctypes.util.find_library('c')
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
