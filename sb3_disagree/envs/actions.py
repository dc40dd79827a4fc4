"""The actions every navigation env shares (Habitat's), and angle arithmetic on headings."""

import math
from enum import IntEnum


class Actions(IntEnum):
    """The discrete actions of the apartment and the scans."""

    TURN_LEFT = 0
    TURN_RIGHT = 1
    MOVE_FORWARD = 2


TURN_LEFT, TURN_RIGHT, MOVE_FORWARD = Actions.TURN_LEFT, Actions.TURN_RIGHT, Actions.MOVE_FORWARD


def wrap(angle: float) -> float:
    """An angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi
