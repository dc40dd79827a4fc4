"""The package as SB3 users meet it: envs registered on import, cheaply; nothing changed in the process."""

import subprocess
import sys


def test_import_registers_every_env_without_loading_a_renderer_or_touching_the_environment():
    code = """
import os, sys
import gymnasium as gym, stable_baselines3, torch  # what they set is theirs (gymnasium hides pygame's prompt)
before = dict(os.environ)
import sb3_disagree
gym.register_envs(sb3_disagree)
heavy = [m for m in ("pyglet", "miniworld", "moderngl", "OpenGL") if m in sys.modules]
assert not heavy, heavy
assert dict(os.environ) == before
for env_id in ("Apartment-v0", "ApartmentState-v0", "Office-v0", "OfficeState-v0"):
    assert "sb3_disagree/" + env_id in gym.registry
env = gym.make("sb3_disagree/ApartmentState-v0", goal="bathtub")
obs, info = env.reset(seed=0)
assert obs.shape == (4,) and info["goal_room"] == "bathroom"
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
