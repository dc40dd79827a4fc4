"""The allocator's settings: freed blocks of a few MB are reused instead of page-faulted in again."""

import subprocess
import sys

import pytest

# Blocks of 4-8 MB allocated and freed while smaller ones stay alive, as in a training step (a replay segment of
# stacked frames, a CNN's activations); print the minor page faults the second pass cost.
CHURN = """
import resource, sys
import numpy as np
from sb3_disagree.run.allocator import keep_freed_memory
if sys.argv[1] == "kept":
    assert keep_freed_memory() and keep_freed_memory()  # applied, and a second call is a no-op
def churn():
    alive = []
    for i in range(200):  # each large block is freed when the next one is made
        block = np.ones((4 + i % 5) << 20, dtype=np.uint8)
        alive.append(np.ones(1 << 20, dtype=np.uint8))
        if len(alive) > 3:
            alive.pop(0)
churn()  # the first pass faults its pages in either way
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
churn()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", CHURN, mode], capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_blocks_are_reused_without_page_faults():
    # By default glibc hands such blocks back to the OS and faults them in again: about 50k pages a pass here.
    default, kept = _faults("default"), _faults("kept")
    assert default > 20_000
    assert kept < 1_000
