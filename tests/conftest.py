import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

import torch as th

sys.path.insert(0, str(Path(__file__).parent))
th.set_num_threads(1)
# The tests never write into the user's cache, nor leave SB3's default log folders (one per learn() without
# a logger) or torch's compile cache folder in the temp dir: they go to one folder, removed when the tests end
# (subprocesses inherit it).
_SCRATCH = tempfile.mkdtemp(prefix="sb3-disagree-tests-")
atexit.register(shutil.rmtree, _SCRATCH, ignore_errors=True)
os.environ["SB3_DISAGREE_CACHE"] = os.path.join(_SCRATCH, "cache")
os.environ["SB3_LOGDIR"] = os.path.join(_SCRATCH, "sb3-logs")
os.environ["TORCHINDUCTOR_CACHE_DIR"] = os.path.join(_SCRATCH, "torchinductor")
