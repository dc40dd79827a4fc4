"""Choosing a run's priors from the zoo, and what the priors' cards tell a mode (JSRL's guide horizon)."""

import numpy as np

from sb3_disagree.options import PriorSet
from sb3_disagree.run.config import RunConfig

def choose_priors(config: RunConfig, env) -> tuple[list[str], list[float], PriorSet]:
    """The priors of a run: by similarity from the zoo, or as named; loaded and checked against the env."""
    from sb3_disagree.language import load_embedding, rank_by_similarity, select_priors
    from sb3_disagree.zoo import Zoo, ZooError

    zoo = Zoo(config.zoo)
    labels = zoo.labels(config.env_id)
    embedding = load_embedding(config.embedding)
    if config.priors == "auto":
        chosen = select_priors(config.goal, labels, embedding, k=2)
    else:
        names = list(config.priors)
        if len(names) < 2:
            raise ValueError(f"--priors needs at least two goals, got {names}")
        if len(set(names)) < len(names):
            raise ValueError(f"--priors names a goal twice: {', '.join(names)}")
        if config.goal in names:
            raise ValueError(f"--priors names the new goal {config.goal!r} itself: the priors are other goals' policies")
        missing = [n for n in names if n not in labels]
        if missing:
            raise ZooError(f"the zoo has no usable prior for {', '.join(missing)} in {config.env_id}")
        sims = dict(rank_by_similarity(config.goal, names, embedding))
        chosen = [(n, sims.get(n, 1.0)) for n in names]
    models = [zoo.load(zoo.get(name, config.env_id), env) for name, _ in chosen]
    return [n for n, _ in chosen], [s for _, s in chosen], PriorSet(models)


def guide_horizon(config: RunConfig, prior_names: list[str]) -> int:
    """The priors' mean episode length on their own goals (their cards' sampled evaluation): where JSRL's guide
    horizon starts."""
    from sb3_disagree.zoo import Zoo

    zoo = Zoo(config.zoo)
    lengths = [zoo.get(name, config.env_id).card.evaluation.get("mean_length") for name in prior_names]
    lengths = [x for x in lengths if x]
    if not lengths:
        raise ValueError("the priors' cards record no evaluation to take JSRL's horizon from; give jsrl_horizon")
    return max(1, int(round(float(np.mean(lengths)))))


