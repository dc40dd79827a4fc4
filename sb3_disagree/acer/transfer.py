"""Starting a new ACER policy from a prior's weights (fine-tuning a prior)."""

from typing import Any

import torch as th

from sb3_disagree.acer.policies import ACERPolicy
from sb3_disagree.acer.torch_layers import LoopFlagsCNN


def transfer_kwargs(prior_policy: Any) -> dict[str, Any]:
    """
    The policy keyword arguments that give a new ACER policy the prior's architecture, its memory included.

    :param prior_policy: An ACER policy (what the zoo's priors are)
    """
    if not isinstance(prior_policy, ACERPolicy):
        raise ValueError(f"fine-tuning starts from an ACER prior; this prior's policy is {type(prior_policy).__name__}")
    return dict(net_arch=prior_policy.net_arch, features_extractor_kwargs=dict(prior_policy.features_extractor_kwargs),
                frame_stack=prior_policy.frame_stack)


@th.no_grad()
def load_prior_weights(policy: ACERPolicy, prior_policy: ACERPolicy) -> list[str]:
    """
    Copy a prior's features extractor, trunk and policy head into ``policy`` (and its average network).

    The Q head is the new policy's own: a prior made by imitation never trained its Q head, and one made
    by RL learned the values of another goal. Where ``policy`` sees a stack of ``k`` observations and the
    prior one, the first layer's weights for the newest observation are the prior's and those for the
    older ones zero; where ``policy`` has loop flags (``LoopFlagsCNN``) and the prior a plain CNN, the prior's CNN
    is the one inside, and the weights that read the flags (after the CNN's features) are zero: either way the new
    policy starts acting exactly as the prior.

    :param policy: The new policy, built with :func:`transfer_kwargs` of the prior
    :param prior_policy: The prior's policy
    :return: The names of the parameters copied
    """
    own, theirs = policy.net.state_dict(), prior_policy.acting_net.state_dict()  # the weights the prior acts with
    copied = []
    flags = getattr(policy.net.features_extractor, "k", 1) - 1 if isinstance(
        policy.net.features_extractor, LoopFlagsCNN) and not isinstance(
        prior_policy.acting_net.features_extractor, LoopFlagsCNN) else 0
    for name, value in theirs.items():
        if name.startswith("q_net.") or name.startswith("qf_net."):
            continue
        if flags and name.startswith("features_extractor."):  # the plain CNN is the one inside the loop flags'
            name = "features_extractor.cnn." + name[len("features_extractor."):]
        if name not in own:
            raise ValueError(f"the prior's parameter {name} has no counterpart in the new policy")
        target = own[name]
        if target.shape != value.shape:
            if flags and target.dim() == 2 and target.shape[1] == value.shape[1] + flags:
                # The layer after the features: the CNN's features first, then the flags, read with zeros.
                target.zero_()
                target[:, :value.shape[1]] = value
            elif target.dim() < 2 or target.shape[0] != value.shape[0] or target.shape[1] % value.shape[1]:
                raise ValueError(f"{name}: the prior's shape {tuple(value.shape)} does not fit {tuple(target.shape)}")
            else:  # A wider input: the stack of frames along the channel axis, the newest last.
                target.zero_()
                target[:, -value.shape[1]:] = value
        else:
            target.copy_(value)
        copied.append(name)
    policy.net.load_state_dict(own)
    policy.sync_averages()
    return copied
