"""
The priors: the zoo of saved policies labelled with their goals (``zoo``), goal words in an embedding
(``language``), choosing a new goal's priors by similarity (``select``) and making new priors (``make``).
"""

from sb3_disagree.priors.language import (Embedding, NotEnoughPriorsError, UnknownWordError, load_embedding,
                                          rank_by_similarity, select_priors)
from sb3_disagree.priors.select import choose_priors, guide_horizon
from sb3_disagree.priors.zoo import DEFAULT_ZOO, Card, Entry, Zoo, ZooError, register_algorithm

__all__ = ["DEFAULT_ZOO", "Card", "Embedding", "Entry", "NotEnoughPriorsError", "UnknownWordError", "Zoo", "ZooError",
           "add_prior", "choose_priors", "guide_horizon", "load_embedding", "make_prior", "rank_by_similarity", "record_evaluations",
           "register_algorithm", "select_priors", "train_dagger", "train_rl"]


def __getattr__(name: str):
    # Making priors needs torch and the algorithms; reading the zoo and choosing priors do not.
    if name in ("add_prior", "make_prior", "record_evaluations", "train_dagger", "train_rl"):
        from sb3_disagree.priors import make

        return getattr(make, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
