"""Environments: the apartment (MiniWorld RGB and a state variant) and its scripted expert."""

import os

from gymnasium.envs.registration import register, registry


def _arrange_headless_pyglet() -> None:
    """MiniWorld draws through pyglet: without a display, pyglet must use its headless (EGL) mode,
    set before anything imports miniworld."""
    if os.environ.get("DISPLAY") or "PYGLET_HEADLESS" in os.environ:
        return
    import pyglet

    pyglet.options["headless"] = True


_arrange_headless_pyglet()
# llvmpipe renders 60x80 frames faster on one thread than it splits them.
os.environ.setdefault("LP_NUM_THREADS", "0")

APARTMENT_ID = "sb3_disagree/Apartment-v0"
APARTMENT_STATE_ID = "sb3_disagree/ApartmentState-v0"
OFFICE_ID = "sb3_disagree/Office-v0"
OFFICE_STATE_ID = "sb3_disagree/OfficeState-v0"

if APARTMENT_ID not in registry:
    register(APARTMENT_ID, entry_point="sb3_disagree.envs.apartment:ApartmentEnv", kwargs={"obs": "rgb"})
    register(APARTMENT_STATE_ID, entry_point="sb3_disagree.envs.apartment:ApartmentEnv", kwargs={"obs": "state"})
    register(OFFICE_ID, entry_point="sb3_disagree.envs.scan:ScanEnv", kwargs={"obs": "rgb"})
    register(OFFICE_STATE_ID, entry_point="sb3_disagree.envs.scan:ScanEnv", kwargs={"obs": "state"})



def make(env_id: str, **kwargs):
    """``gym.make`` after this package's environments are registered: picklable, so a worker process
    (SubprocVecEnv, Ray) that has not imported the package can build them too."""
    import gymnasium as gym

    return gym.make(env_id, **kwargs)


from sb3_disagree.envs.apartment import ApartmentEnv  # noqa: E402
from sb3_disagree.envs.layout import Layout, default_layout  # noqa: E402

__all__ = ["OFFICE_ID", "OFFICE_STATE_ID", "APARTMENT_ID", "APARTMENT_STATE_ID", "ApartmentEnv", "Layout", "default_layout", "make"]
