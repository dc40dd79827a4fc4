"""The greedy phase once the run is ready: a budget that grows where a goal is slow to learn."""

from typing import Any, Optional

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.finish.greedy_phase import GreedyPhase

NEVER = float("inf")


class StartWhenReady(BaseCallback):
    """
    Start the greedy phase (and the harvest over it) at its planned step only if the run's training success over its
    last 100 episodes has reached ``ready`` by then; otherwise train on with the mode's own behaviour and start the
    phase at the first step where it has, or at ``latest`` at the latest. The run then ends ``length`` env steps after
    the phase began (ACER's ``end_at``). A run ready on time is exactly the run without this callback.

    :param phase: The run's greedy phase (its ``start`` is set here)
    :param harvest: The harvest over the phase (its ``start`` moves with the phase's), or None
    :param planned: The env step at which the phase starts if the run is ready by then
    :param latest: The env step at which the phase starts whatever the training success
    :param length: The phase's env steps
    :param harvest_length: The harvest's env steps, the run's last (it starts with the phase where they are equal)
    :param ready: Training success (last 100 episodes, ``rollout/success_rate``) the run must show
    :param started: The env step at which the phase began before the run was interrupted: a resumed run keeps it
        (its training success is not saved, and the phase's own episodes would judge it)
    """

    def __init__(self, phase: GreedyPhase, harvest: Optional[Any], planned: int, latest: int, length: int,
                 harvest_length: int, ready: float, started: Optional[int] = None) -> None:
        super().__init__()
        if not planned <= latest:
            raise ValueError(f"the latest start of the greedy phase ({latest}) is before its planned one ({planned})")
        self.phase, self.harvest = phase, harvest
        self.planned, self.latest, self.length, self.ready = planned, latest, length, ready
        self.harvest_length = harvest_length
        self.started = started  # the env step at which the phase began

    def success(self) -> float:
        """The training success over the last 100 episodes; 0 until there are 100 (early on, the episodes that have
        ended are mostly the successful ones)."""
        buffer = self.model.ep_success_buffer
        return float(np.mean(buffer)) if len(buffer) == buffer.maxlen else 0.0

    def _on_training_start(self) -> None:
        if self.started is not None:
            self._set_start(self.started)
            self.model.end_at(self.started + self.length)

    def state(self) -> dict[str, Optional[int]]:
        """What a checkpoint keeps of it: where the phase began (None while it has not)."""
        return {"greedy_start": self.started}

    def _on_step(self) -> bool:
        if self.started is not None or self.num_timesteps < self.planned:
            return True
        if self.success() >= self.ready or self.num_timesteps >= self.latest:
            # Ready at the first look: the phase keeps its planned start (the run is the one without this callback).
            self.started = self.planned if self.phase.start == self.planned else self.num_timesteps
            self._set_start(self.started)
            self.model.end_at(self.started + self.length)
        else:
            self._set_start(NEVER)
        return True

    def _set_start(self, step: float) -> None:
        self.phase.start = step
        if self.harvest is not None:
            self.harvest.start = step + self.length - self.harvest_length
