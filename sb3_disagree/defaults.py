"""The defaults several modules share, defined once: the environment, and the env seeds of evaluations.

A run with seed ``s`` trains on env seeds ``s .. s + n_envs - 1``; its evaluations use seeds far from those,
so that the policy alone is always measured from starts it never trained on.
"""

DEFAULT_ENV = "sb3_disagree/Apartment-v0"
EVAL_SEED_OFFSET = 10_000  # the periodic evaluations along a run: seed + 10 000
FINAL_EVAL_SEED_OFFSET = 20_000  # the evaluation after a run (result.json, the model card, dopt eval): seed + 20 000
PRIOR_CARD_SEED = 10_000  # a prior's evaluation on its card
PRIOR_VALIDATION_SEED = 20_000  # DAgger's per-round validation of a prior
CONSISTENCY_SEED_OFFSET = 30_000  # the greedy-consistency phase after a run (dopt consistency): seed + 30 000
VALIDATION_SEED_OFFSET = 40_000  # the validation of the greedy-consistency fits (consistency_validation)
VALIDATION_MAX_STEPS = 200  # a validation episode not at the goal by then fails (a greedy success takes ~80)
