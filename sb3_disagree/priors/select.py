"""Choosing a new goal's priors from the zoo (paper section 3.1), and what their cards tell a mode (JSRL's guide
horizon)."""

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np

from sb3_disagree.priors.language import load_embedding, rank_by_similarity, select_priors
from sb3_disagree.priors.zoo import Zoo, ZooError

PathLike = Union[str, Path, None]


def choose_priors(goal: str, env_id: str, env: Any, priors: Union[str, Sequence[str]] = "auto", zoo: PathLike = None,
                  embedding: PathLike = None, k: int = 2, trust: bool = False) -> tuple[list[str], list[Optional[float]], list[Any]]:
    """
    The priors of a new goal, loaded and checked against the env: the ``k`` zoo entries whose goals are nearest
    ``goal`` in the embedding (``priors="auto"``), or the goals named. Named priors load no embedding; their
    similarity is None.

    :param goal: The new goal
    :param env_id: The environment's id (the zoo's entries are per env id)
    :param env: The (Vec)Env the priors must act in: their spaces are checked against it
    :param priors: "auto" or the goals of the priors
    :param zoo: The zoo folder (default: the shipped zoo)
    :param embedding: Word vectors file (default: MiniLM)
    :param trust: Also read an embedding saved as a pickle (``load_embedding``)
    :param k: Number of priors chosen by similarity
    :return: The priors' goals, their similarities to ``goal`` and the loaded SB3 models
    """
    zoo_ = Zoo(zoo)
    if not zoo_.root.is_dir():  # a zoo made by commands first (docs/zoo.md), not made yet here
        raise ZooError(f"the zoo {zoo_.root} does not exist; make it first (dopt priors train --zoo {zoo_.root} ...)")
    labels = zoo_.labels(env_id, env.observation_space, env.action_space)
    if priors == "auto":
        chosen = select_priors(goal, labels, load_embedding(embedding, trust=trust), k=k)
    else:
        names = list(priors)
        if len(names) < 2:
            raise ValueError(f"--priors needs at least two goals, got {names}")
        if len(set(names)) < len(names):
            raise ValueError(f"--priors names a goal twice: {', '.join(names)}")
        if goal in names:
            raise ValueError(f"--priors names the new goal {goal!r} itself: the priors are other goals' policies")
        missing = [n for n in names if n not in labels]
        if missing:
            raise ZooError(f"the zoo has no usable prior for {', '.join(missing)} in {env_id}")
        chosen = [(n, None) for n in names]
    models = [zoo_.load(zoo_.get(name, env_id), env) for name, _ in chosen]
    return [n for n, _ in chosen], [s for _, s in chosen], models


def guide_horizon(env_id: str, prior_names: Sequence[str], zoo: PathLike = None) -> int:
    """The priors' mean episode length on their own goals (their cards' sampled evaluation): where JSRL's guide
    horizon starts."""
    zoo_ = Zoo(zoo)
    lengths = [zoo_.get(name, env_id).card.evaluation.get("mean_length") for name in prior_names]
    lengths = [x for x in lengths if x]
    if not lengths:
        raise ValueError("the priors' cards record no evaluation to take JSRL's horizon from; give jsrl_horizon")
    return max(1, int(round(float(np.mean(lengths)))))


def rank_entries(goal: str, entries: Sequence[Any], embedding: Any, k: int = 2) -> tuple[dict[str, float], set[str]]:
    """
    The zoo's entries by similarity to ``goal``, as the method would choose among them.

    :param goal: The new goal
    :param entries: Zoo entries (:meth:`Zoo.entries`); damaged ones are ranked but never chosen
    :param embedding: The word embedding
    :param k: How many priors the goal would use
    :return: Each entry's similarity to ``goal``, and the goals of the ``k`` usable ones chosen
    """
    usable = {e.goal for e in entries if not e.problem}
    ranked = rank_by_similarity(goal, [e.goal for e in entries], embedding)
    return dict(ranked), {label for label, _ in [r for r in ranked if r[0] in usable][:k]}
