"""The paper's room-sensor oracle: the environment's room report replaces the disagreement gate."""

from typing import Any

import numpy as np

from sb3_disagree.options.base import OptionsBehaviour


class RoomSensorOptions(OptionsBehaviour):
    """
    The paper's oracle: follow the priors while the environment reports the agent outside the goal's
    room (``info["room"] != info["goal_room"]``), explore inside it. The entropy branch is as in
    :class:`DisagreementOptions`, so the priors fade as the new policy grows certain.

    :param priors: The priors
    :param entropy_offset: Enter the prior branch when ``U(0, 1) < H(pi) - entropy_offset``
    :param seed: Seed of the branch draws
    """

    def _gate(self, observations: Any, prior_probs: Any, infos: list[dict], episode_starts: np.ndarray,
              branch: np.ndarray) -> np.ndarray:
        # Without a room report (no info yet) the agent is taken to be outside the goal room.
        return np.array(["room" not in info or info["room"] != info.get("goal_room") for info in infos])
