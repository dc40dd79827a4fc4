"""The model a run trains: ACER in the run's mode (from a prior's weights, with distillation, ...) or PPO."""

from pathlib import Path
from typing import Optional

from sb3_disagree.acer import ACER
from sb3_disagree.acer.torch_layers import loop_flags_kwargs
from sb3_disagree.acer.transfer import load_prior_weights, transfer_kwargs
from sb3_disagree.options import PriorSet
from sb3_disagree.run.config import PPO_KWARGS, RunConfig

def algorithm_of(mode: str) -> type:
    """The SB3 algorithm class a mode trains: PPO for "ppo", ACER for every other."""
    if mode == "ppo":
        from stable_baselines3 import PPO

        return PPO
    return ACER


def ppo_schedules() -> dict:
    """PPO's learning rate and clip range as the "ppo" mode trains with them: ``PPO_KWARGS``' values falling linearly
    to 0 over the budget (rl-zoo3's "lin_" values)."""
    lr, clip = PPO_KWARGS["learning_rate"], PPO_KWARGS["clip_range"]
    return dict(learning_rate=lambda p: p * lr, clip_range=lambda p: p * clip)


def load_model(config: dict, path: Path, env=None, behaviour=None, device: str = "auto", trust: bool = False):
    """
    A run's saved model, opened without unpickling what the file carries (``sb3_disagree.loading``) unless
    trusted: PPO's schedules come from the mode's settings, ACER's from its plain fields.

    :param config: The run's saved configuration (``config.yaml``)
    :param path: Its model file (``model.zip``, or a checkpoint's)
    :param env: Envs to continue training in
    :param behaviour: ACER's behaviour to continue training with
    :param device: Torch device
    :param trust: Unpickle the file as SB3 does
    """
    from sb3_disagree.loading import load

    mode = config.get("mode", "disagreement")
    if mode == "ppo":
        return load(path, algorithm_of(mode), env=env, device=device, trust=trust, schedules=ppo_schedules())
    return load(path, ACER, env=env, device=device, trust=trust, behaviour=behaviour,
                overlap=bool(config.get("overlap", False)))


def new_model(config: RunConfig, env, behaviour, priors: Optional[PriorSet]):
    """The model a new run trains: ACER with the run's settings (from a prior's weights for "finetune", with
    kickstarting's distillation for "kickstart"), or SB3's PPO with ``PPO_KWARGS`` for "ppo"."""
    policy = "CnnPolicy" if len(env.observation_space.shape) == 3 else "MlpPolicy"
    if config.mode == "ppo":
        from stable_baselines3 import PPO

        kwargs = {k: v for k, v in PPO_KWARGS.items() if k not in ("learning_rate", "clip_range")}
        return PPO(policy, env, seed=config.seed, **ppo_schedules(), **kwargs)
    acer_kwargs = dict(config.acer_kwargs)
    policy_kwargs = dict(acer_kwargs.pop("policy_kwargs", {}))
    from_prior = config.mode == "finetune" or config.init == "prior"
    if from_prior:  # the most similar prior's architecture, and below its weights
        policy_kwargs.update(transfer_kwargs(priors.priors[0].policy))
    if config.frame_stack > 1:
        policy_kwargs["frame_stack"] = config.frame_stack
    if config.loop_flags:  # validate() has checked the observations are images
        # from a prior: its CNN's settings (its features), inside the loop flags' extractor
        extractor = {k: v for k, v in policy_kwargs.get("features_extractor_kwargs", {}).items() if k != "frame_stack"}
        policy_kwargs.update(loop_flags_kwargs(config.frame_stack, **(extractor if from_prior else {})))
    model = ACER(policy, env, seed=config.seed, behaviour=behaviour, overlap=config.overlap,
                 policy_kwargs=policy_kwargs, **acer_kwargs)
    if from_prior:
        load_prior_weights(model.policy, priors.priors[0].policy)
    return model


