"""
The finish: what makes the policy a run hands over work greedily on its own, whatever the mode trained it. The greedy
phase (``greedy_phase``: the last steps act by the argmax), the harvest of the run's own successful episodes and the
validated fit of ``model.zip`` to their loop-free paths, and the greedy-consistency phase of ``dopt consistency`` and
the priors (``consistency``), and the phase's wait until the run is ready (``ready``: the budget grows meanwhile). It
observes the rollouts through the behaviour hook and callbacks; of ACER it needs only ``end_at``.
"""

from sb3_disagree.finish.consistency import HarvestLabels, RoundStats, greedy_consistency
from sb3_disagree.finish.greedy_phase import GreedyPhase
from sb3_disagree.finish.ready import StartWhenReady

__all__ = ["GreedyPhase", "HarvestLabels", "RoundStats", "StartWhenReady", "greedy_consistency"]
