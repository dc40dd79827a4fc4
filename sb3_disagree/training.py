"""The names of ``sb3_disagree.run`` under the module they lived in before (kept for earlier imports)."""

from sb3_disagree.run import *  # noqa: F401,F403
from sb3_disagree.run import __all__  # noqa: F401
