"""
Environments: the apartment (MiniWorld RGB and a state variant), the office scan, and their scripted expert.

Importing this package registers them with Gymnasium (``import sb3_disagree`` does it too); nothing
imports MiniWorld, pyglet or OpenGL until an RGB environment draws its first frame.
"""

from gymnasium.envs.registration import register, registry

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
