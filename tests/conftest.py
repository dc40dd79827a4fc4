import os
import sys
import tempfile
from pathlib import Path

import torch as th

sys.path.insert(0, str(Path(__file__).parent))
th.set_num_threads(1)
# The tests never write into the user's cache.
os.environ["SB3_DISAGREE_CACHE"] = tempfile.mkdtemp(prefix="sb3-disagree-test-cache-")
