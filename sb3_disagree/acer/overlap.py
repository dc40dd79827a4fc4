"""
ACER's overlapped trainer: the replay updates of one segment run in a second thread while the next segment
is collected (faster on two cores; docs/acer.md, "Overlapped updates").

Threads: the caller sets torch's thread count (the CLI and the experiment runner do). While both threads
work they split it, one half each (one each on two cores: measured faster than two each); the on-policy
update, when the other thread is idle, takes all of it; leaving restores the caller's count.
"""

import contextlib
import copy
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np
import torch as th

from sb3_disagree.acer.buffers import Segment
from sb3_disagree.acer.policies import ACERPolicy


def copy_learner(learner: ACERPolicy, policy: ACERPolicy) -> None:
    """Copy the learner (both networks and the optimizer state) into ``policy``. The optimizer's state is
    deep-copied: ``load_state_dict`` would share its tensors, which the learner keeps updating in place."""
    policy.load_state_dict(learner.state_dict())
    policy.optimizer.load_state_dict(copy.deepcopy(learner.optimizer.state_dict()))


@contextlib.contextmanager
def overlapped_updates(model: Any) -> Iterator[Callable[[Segment], None]]:
    """
    A function that learns from each collected segment: it does the on-policy update on a learner copy of
    the policy, copies the learner into ``model.policy`` (which the rollouts act with) and hands the segment's
    replay updates to a second thread. Leaving the context (also on an interruption) waits for the last replay
    updates and makes the carried ones: what was collected is learned.

    :param model: The ACER model whose ``learn`` collects the segments (not imported here: ACER imports this)
    """
    learner = copy.deepcopy(model.policy)
    # The replay draws get their own generators (counts here, segments in the worker): the rollouts in this
    # thread may draw from the global one.
    seeds = np.random.randint(2**31, size=2)
    counts, samples = np.random.default_rng(seeds[0]), np.random.default_rng(seeds[1])
    cap = int(np.ceil(model.replay_ratio)) + 1
    pending: list[Future] = []
    backlog = 0

    def finish_replays() -> None:
        if pending:
            model.logger.record("train/replay_updates", pending[0].result())  # still pending if interrupted
            pending.clear()

    def hand_over(segment: Segment) -> None:
        nonlocal backlog
        finish_replays()
        th.set_num_threads(threads)  # the other thread is idle here
        model.record_train(model.on_policy_update(segment, learner))
        th.set_num_threads(half)
        copy_learner(learner, model.policy)
        # At most `cap` replay updates per segment, the rest carried to the next: a large Poisson draw
        # would otherwise keep the rollouts waiting while a small one leaves the worker idle.
        backlog += model.replay_count(counts)
        n_replay = min(backlog, cap)
        backlog -= n_replay
        batches = None
        if model.average_ahead:  # the worker is idle until the submit below
            th.set_num_threads(threads)
            batches = model.replay_references(learner, n_replay, samples)
            th.set_num_threads(half)
        # The weights of this hand-over, as the sequential loop would use: the worker must not read the progress
        # that the next rollout moves on (the run would depend on the threads' timing).
        pending.append(replays.submit(model.replay, learner, n_replay, samples, batches, model.scheduled_coefs()))

    threads = th.get_num_threads()
    half = max(1, threads // 2)
    th.set_num_threads(half)
    with ThreadPoolExecutor(1, "acer-replay", initializer=th.set_num_threads, initargs=(half,)) as replays:
        try:
            yield hand_over
        finally:
            finish_replays()
            th.set_num_threads(threads)
            model.replay(learner, backlog, samples)  # what was earned is learned
            copy_learner(learner, model.policy)
