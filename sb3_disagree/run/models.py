"""The model a run trains: ACER in the run's mode (from a prior's weights, with distillation, ...) or PPO."""

from typing import Optional

from sb3_disagree.acer import ACER
from sb3_disagree.acer.torch_layers import loop_flags_kwargs
from sb3_disagree.acer.transfer import load_prior_weights, transfer_kwargs
from sb3_disagree.options import PriorSet
from sb3_disagree.run.config import KICKSTART, PPO_KWARGS, RunConfig

def algorithm_of(mode: str) -> type:
    """The SB3 algorithm class a mode trains: PPO for "ppo", ACER for every other."""
    if mode == "ppo":
        from stable_baselines3 import PPO

        return PPO
    return ACER


def new_model(config: RunConfig, env, behaviour, priors: Optional[PriorSet]):
    """The model a new run trains: ACER with the run's settings (from a prior's weights for "finetune", with
    kickstarting's distillation for "kickstart"), or SB3's PPO with ``PPO_KWARGS`` for "ppo"."""
    policy = "CnnPolicy" if len(env.observation_space.shape) == 3 else "MlpPolicy"
    if config.mode == "ppo":
        from stable_baselines3 import PPO

        kwargs = dict(PPO_KWARGS)
        lr, clip = kwargs.pop("learning_rate"), kwargs.pop("clip_range")
        return PPO(policy, env, seed=config.seed, learning_rate=lambda p: p * lr, clip_range=lambda p: p * clip,
                   **kwargs)
    acer_kwargs = dict(config.acer_kwargs)
    if config.mode == "kickstart":
        acer_kwargs = {**KICKSTART, **acer_kwargs}
    policy_kwargs = dict(acer_kwargs.pop("policy_kwargs", {}))
    from_prior = config.mode == "finetune" or config.init == "prior"
    if from_prior:  # the most similar prior's architecture, and below its weights
        policy_kwargs.update(transfer_kwargs(priors.priors[0].policy))
    if config.frame_stack > 1:
        policy_kwargs["frame_stack"] = config.frame_stack
    if config.loop_flags:  # validate() has checked the observations are images
        policy_kwargs.update(loop_flags_kwargs(config.frame_stack))
    model = ACER(policy, env, seed=config.seed, behaviour=behaviour, overlap=config.overlap,
                 policy_kwargs=policy_kwargs, **acer_kwargs)
    if from_prior:
        load_prior_weights(model.policy, priors.priors[0].policy)
    return model


