"""
Making priors: imitation of an environment's scripted expert with DAgger-style relabelling, or
reinforcement learning (ACER, PPO), then evaluation from the environment's own start distribution.

An environment offers an expert by a method ``expert_action()`` that returns the expert's action for
its current state (the apartment does); DAgger needs nothing else.
"""

import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.vec_env import VecEnv

from sb3_disagree.acer import ACER
from sb3_disagree.acer.memory import LinkedFrames, push_frames
from sb3_disagree.acer.torch_layers import CNN_SEES, loop_flags_kwargs
from sb3_disagree.defaults import PRIOR_VALIDATION_SEED
from sb3_disagree.envs.vec import make_vec
from sb3_disagree.evaluation import Evaluation, evaluate
from sb3_disagree.loggers import silent_logger

METHODS = ("dagger", "acer", "ppo")
# Small image networks keep a zoo of ten priors well under 60 MB.
PRIOR_POLICY_KWARGS = {"CnnPolicy": dict(features_extractor_kwargs=dict(features_dim=128)), "MlpPolicy": {}}


def policy_name(env: VecEnv) -> str:
    return "CnnPolicy" if is_image_space(env.observation_space) else "MlpPolicy"


def train_dagger(
    env: VecEnv,
    seed: int = 0,
    rounds: int = 6,
    steps_per_round: int = 3_000,
    epochs: int = 6,
    batch_size: int = 128,
    learning_rate: float = 1e-3,
    max_episode_steps: int = 200,
    final_epochs: int = 0,
    validation_env: Optional[VecEnv] = None,
    validation_episodes: int = 0,
    validation_seed: int = PRIOR_VALIDATION_SEED,
    learner_actions: str = "sampled",
    frame_stack: int = 1,
    loop_flags: bool = False,
    flags_cnn: str = "newest",
    expert_no_return: bool = False,
    progress: Optional[Callable[[str], None]] = None,
) -> tuple[ACER, dict[str, Any]]:
    """
    DAgger: the first round follows the expert; later rounds follow the learner with probability
    ``1 - 0.5 ** round`` and the expert otherwise, and every visited state is labelled with the expert's
    action; after each round the policy head is fitted to all labels so far (cross-entropy).

    :param env: The VecEnv to imitate in; its envs have ``expert_action()``
    :param seed: Seed of the policy and the rollouts
    :param rounds: Data-collection rounds
    :param steps_per_round: Labelled env steps per round
    :param epochs: Passes over the aggregated data after each round
    :param batch_size: Minibatch size
    :param learning_rate: Adam's learning rate
    :param max_episode_steps: Rollouts restart after this many steps (a stuck learner teaches little more)
    :param final_epochs: Extra passes over the final aggregate with the learning rate decayed to zero
        (the per-round fits stop short of fitting the labels; these close the gap)
    :param validation_env: Where each round's policy is evaluated when ``validation_episodes > 0``; the
        policy of the round with the highest success is returned (DAgger's "best policy of the sequence"),
        rather than the last one
    :param validation_episodes: Episodes per validation (0: return the last round's policy)
    :param validation_seed: Env seed of every validation, so that each round meets the same starts
    :param learner_actions: How the learner acts in the rounds it leads: "sampled", or "greedy" (its argmax, as
        SB3's ``evaluate_policy`` acts), so that the states where a greedy policy gets stuck (walking into a
        wall) are visited and labelled; validation then evaluates greedily too
    :param frame_stack: Number of recent observations the policy sees (its memory, carried by ``predict``'s
        ``state``); the labels are fitted on the stacks the learner saw
    :param loop_flags: The policy's CNN sees the newest frame, and flags say whether it equals each older frame of
        the stack (``LoopFlagsCNN``: pressed against a wall, turning back and forth); needs ``frame_stack`` >= 2
        and image observations
    :param flags_cnn: With loop flags, what the CNN sees: "newest" (the newest frame) or "stack" (every frame of the
        stack, as without flags)
    :param expert_no_return: Label with the expert that never stays in place (a blocked move) nor returns to the pose
        before the last step (``expert_action(no_return=True)``): the memoryless expert's receding horizon holds it
        in such loops from some poses (the office: 15 of 300 sofa episodes), and the prior learns them
    :param progress: Called with a line of text after each round
    :return: An ACER model whose policy imitates the expert, and a record of the training
    """
    if learner_actions not in ("sampled", "greedy"):
        raise ValueError(f"learner_actions must be 'sampled' or 'greedy', got {learner_actions!r}")
    greedy = learner_actions == "greedy"
    name = policy_name(env)
    policy_kwargs = dict(PRIOR_POLICY_KWARGS[name], frame_stack=frame_stack)
    if flags_cnn not in CNN_SEES or (flags_cnn != "newest" and not loop_flags):
        raise ValueError(f"--flags-cnn must be one of {CNN_SEES}, and 'stack' needs --loop-flags; got {flags_cnn!r}"
                         f"{'' if loop_flags else ' without --loop-flags'}")
    if loop_flags:
        if frame_stack < 2 or name != "CnnPolicy":
            raise ValueError("loop flags compare the newest frame with older ones: they need --frame-stack >= 2 and "
                             f"image observations, got {frame_stack} frame(s) of {env.observation_space}")
        policy_kwargs.update(loop_flags_kwargs(frame_stack, **policy_kwargs["features_extractor_kwargs"],
                                               cnn_sees=flags_cnn))
    model = ACER(name, env, seed=seed, policy_kwargs=policy_kwargs)
    env = model.get_env()  # as the policy sees it (channel-first images)
    expert_kwargs = {"no_return": True} if expert_no_return else {}  # an env's expert_action() may take none
    policy = model.policy
    optimizer = th.optim.Adam(policy.net.parameters(), lr=learning_rate)
    rng = np.random.default_rng(seed)
    # Labels are kept with single frames linked to their predecessors, and the stacks rebuilt per minibatch:
    # k-frame stacks of 60x80 images would take k times the memory (tens of GB over many rounds).
    data_obs: list[np.ndarray] = []
    data_prev: list[np.ndarray] = []
    data_act: list[np.ndarray] = []
    previous = np.full(env.num_envs, -1)
    obs = env.reset()
    stack = push_frames(None, obs, None, frame_stack)  # what the learner sees: obs itself without memory
    ep_len = np.zeros(env.num_envs, dtype=int)
    start = time.perf_counter()
    validation: list[float] = []
    best: Optional[dict[str, th.Tensor]] = None
    for r in range(rounds):
        beta = 0.5 ** r  # probability of executing the expert's own action
        collected = 0
        while collected < steps_per_round:
            labels = np.asarray(env.env_method("expert_action", **expert_kwargs), dtype=np.int64)
            here = len(data_obs) * env.num_envs + np.arange(env.num_envs)
            data_obs.append(np.array(obs))
            data_prev.append(previous)
            data_act.append(labels)
            if r == 0:
                actions = labels
            else:
                with th.no_grad():
                    learner = policy._predict(th.as_tensor(stack, device=policy.device), deterministic=greedy)
                actions = np.where(rng.random(env.num_envs) < beta, labels, learner.cpu().numpy())
            obs, _, dones, _ = env.step(actions)
            ep_len = np.where(dones, 0, ep_len + 1)
            if (ep_len >= max_episode_steps).any():
                obs = env.reset()
                ep_len[:] = 0
                dones = np.ones(env.num_envs, dtype=bool)
            stack = push_frames(stack, obs, dones, frame_stack)
            previous = np.where(dones, -1, here)
            collected += env.num_envs
        x = np.concatenate(data_obs)
        if frame_stack > 1:
            x = LinkedFrames(x, np.concatenate(data_prev), frame_stack)
        y = np.concatenate(data_act)
        loss, accuracy = _fit(policy, optimizer, x, y, epochs, batch_size, rng)
        line = f"round {r + 1}/{rounds}: {len(y)} labels, loss {loss:.3f}, accuracy {accuracy:.3f}"
        if validation_env is not None and validation_episodes > 0:
            validation_env.seed(validation_seed)
            validation.append(evaluate(model, validation_env, validation_episodes, deterministic=greedy).success_rate)
            if validation[-1] >= max(validation):  # ties go to the later round, which has seen more labels
                best = {k: v.clone() for k, v in policy.net.state_dict().items()}
            line += f", validation success {validation[-1]:.2f}"
        if progress:
            progress(line)
    record = {"method": "dagger", "steps": int(len(y)), "seed": seed, "rounds": rounds, "epochs": epochs,
              "final_epochs": final_epochs, "learner_actions": learner_actions, "frame_stack": frame_stack,
              "loop_flags": loop_flags, **({"flags_cnn": flags_cnn} if loop_flags else {}),
              **({"expert_no_return": True} if expert_no_return else {})}
    if validation:
        selected = int(np.flatnonzero(np.asarray(validation) == max(validation))[-1])
        policy.net.load_state_dict(best)
        record.update(validation_episodes=validation_episodes, validation_seed=validation_seed,
                      validation_success=validation, selected_round=selected + 1)
        if progress:
            progress(f"kept round {selected + 1} (validation success {validation[selected]:.2f})")
    if final_epochs > 0:  # from the kept round's policy
        schedule = th.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=final_epochs)
        for _ in range(final_epochs):
            loss, accuracy = _fit(policy, optimizer, x, y, 1, batch_size, rng)
            schedule.step()
        if progress:
            progress(f"final {final_epochs} epochs: loss {loss:.3f}, accuracy {accuracy:.3f}")
    record.update(final_loss=loss, final_accuracy=accuracy)
    # The average network starts where the imitated policy is, so that ACER fine-tuning begins consistent.
    policy.sync_averages()
    model.num_timesteps = int(len(y))
    record["seconds"] = round(time.perf_counter() - start, 1)
    return model, record


def _fit(policy, optimizer, x: Union[np.ndarray, LinkedFrames], y: np.ndarray, epochs: int, batch_size: int,
         rng: np.random.Generator) -> tuple[float, float]:
    policy.set_training_mode(True)
    device = policy.device
    for _ in range(epochs):
        order = rng.permutation(len(y))
        losses, correct = [], 0
        for i in range(0, len(y), batch_size):
            idx = order[i:i + batch_size]
            obs = th.as_tensor(x[idx], device=device)
            target = th.as_tensor(y[idx], device=device)
            logits = policy.net.logits(policy.extract_features(obs, policy.net.features_extractor))
            loss = th.nn.functional.cross_entropy(logits, target)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(loss.item())
            correct += int((logits.argmax(-1) == target).sum())
    policy.set_training_mode(False)
    return float(np.mean(losses)), correct / len(y)


def train_rl(env: VecEnv, method: str, steps: int, seed: int = 0, progress_bar: bool = False) -> tuple[BaseAlgorithm, dict]:
    """
    Reinforcement learning from the environment's reward.

    :param env: The VecEnv
    :param method: "acer" or "ppo"
    :param steps: Env steps
    :param seed: Seed
    :param progress_bar: Show SB3's progress bar
    """
    name = policy_name(env)
    start = time.perf_counter()
    if method == "acer":
        model: BaseAlgorithm = ACER(name, env, seed=seed, policy_kwargs=PRIOR_POLICY_KWARGS[name])
    elif method == "ppo":
        from stable_baselines3 import PPO

        model = PPO(name, env, seed=seed, policy_kwargs=PRIOR_POLICY_KWARGS[name])
    else:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    model.set_logger(silent_logger())
    model.learn(steps, progress_bar=progress_bar)
    return model, {"method": method, "steps": steps, "seed": seed, "seconds": round(time.perf_counter() - start, 1)}


def evaluate_entry(zoo: Any, entry: Any, episodes: int, deterministic: bool, seed: int,
                   progress: Optional[Callable[[int], None]] = None) -> Evaluation:
    """
    A zoo entry alone for some episodes on 4 envs seeded from ``seed``.

    :param zoo: The :class:`~sb3_disagree.priors.zoo.Zoo`
    :param entry: Its entry
    :param episodes: Number of episodes
    :param deterministic: Greedy actions if True, sampled otherwise
    :param seed: Env seed of the first env
    :param progress: Called with the number of finished episodes
    """
    return _evaluate_model(lambda venv: zoo.load(entry, venv, device="cpu"), entry, episodes, deterministic, seed,
                           progress)


def _evaluate_model(load: Callable[[VecEnv], BaseAlgorithm], entry: Any, episodes: int, deterministic: bool, seed: int,
                    progress: Optional[Callable[[int], None]] = None) -> Evaluation:
    """A model (given by ``load``) alone for some episodes on 4 envs of a zoo entry's goal, seeded from ``seed``."""
    venv = make_vec(entry.env_id, entry.goal, entry.card.env_kwargs if entry.card else {}, n_envs=4, seed=seed)
    try:
        return evaluate(load(venv), venv, episodes, deterministic, progress)
    finally:
        venv.close()


def make_prior(zoo: Any, goal: str, env_id: str, method: str = "dagger", steps: int = 200_000, n_envs: int = 4,
               seed: int = 0, episodes: int = 100, replace: bool = False, consistency_rounds: int = 0,
               consistency_steps: int = 20_000, consistency_loop_uniform: float = 0.5,
               consistency_validation_episodes: int = 0, consistency_expert_in_loops: bool = False, command: str = "",
               progress: Optional[Callable[[str], None]] = None, **dagger_kwargs: Any) -> tuple[Any, dict[str, Any]]:
    """
    Train a prior, add it to the zoo, and record its evaluation alone (greedy and sampled) on its card: what
    ``dopt priors train`` does, in one call.

    :param zoo: The :class:`~sb3_disagree.priors.zoo.Zoo` to add it to
    :param goal: The goal it learns to reach
    :param env_id: The environment
    :param method: "dagger" (imitate the env's expert), "acer" or "ppo"
    :param steps: Env steps for acer/ppo
    :param n_envs: Parallel envs
    :param seed: Seed of the policy and the rollouts
    :param episodes: Evaluation episodes each way for the card (0: none)
    :param replace: Replace an existing prior for this goal
    :param consistency_rounds: After training, rounds of the greedy-consistency phase (the prior acts greedily,
        sampling where it loops, and is fitted to the loop-free paths of its episodes that reach the goal; the
        phase ``dopt consistency`` runs on a new policy), on env seeds ``seed + CONSISTENCY_SEED_OFFSET``; 0: none
    :param consistency_steps: Env steps per round of that phase
    :param consistency_loop_uniform: In a loop, the phase draws from ``(1 - u) pi + u / n``: a prior imitating an
        expert is sharp, and sampling from pi alone where it turns back and forth repeats the turn
    :param consistency_validation_episodes: Greedy validation episodes after each epoch of that phase, from
        DAgger's validation starts: each round keeps its best epoch and the phase its best round (0: none)
    :param consistency_expert_in_loops: In that phase, label every visit of a pose an episode visits more than
        once with the env's expert, in failed episodes too (a memoryless or short-memory greedy prior's failures
        are cycles over a few poses, docs/method.md)
    :param command: The command that made it, for the card
    :param progress: Called with a line of text as training goes (DAgger's rounds, the phase's rounds)
    :param dagger_kwargs: :func:`train_dagger`'s own settings (rounds, epochs, validation_episodes, ...)
    :return: The zoo entry (as read back) and the evaluations by label ("greedy", "sampled")
    """
    from sb3_disagree.defaults import PRIOR_VALIDATION_SEED

    zoo.check_writable()  # before any training
    if method not in METHODS:
        raise ValueError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    if not replace and any(e.goal == goal for e in zoo.entries(env_id)):
        raise ValueError(f"the zoo already has a prior for {goal!r} in {env_id}; pass --replace to retrain it")
    if dagger_kwargs.get("validation_episodes", 0) < 0:
        raise ValueError(f"--validation-episodes must be >= 0, got {dagger_kwargs['validation_episodes']}")
    if (consistency_rounds < 0 or (consistency_rounds and consistency_steps < n_envs)
            or not 0 <= consistency_loop_uniform <= 1 or consistency_validation_episodes < 0):
        raise ValueError(f"--consistency-rounds must be >= 0, --consistency-steps >= {n_envs} (one per env), "
                         f"--consistency-loop-uniform in [0, 1] and --consistency-validation-episodes >= 0, got "
                         f"{consistency_rounds}, {consistency_steps}, {consistency_loop_uniform} and "
                         f"{consistency_validation_episodes}")
    if consistency_rounds and method == "ppo":
        raise ValueError("the greedy-consistency phase refines an ACER policy (--method dagger or acer), not PPO")
    venv = make_vec(env_id, goal, n_envs=n_envs, seed=seed)
    if method == "dagger":
        validation = dagger_kwargs.get("validation_episodes", 0)
        validation_env = make_vec(env_id, goal, n_envs=n_envs, seed=PRIOR_VALIDATION_SEED) if validation else None
        model, record = train_dagger(venv, seed=seed, validation_env=validation_env,
                                     validation_seed=PRIOR_VALIDATION_SEED, progress=progress, **dagger_kwargs)
    else:
        model, record = train_rl(venv, method, steps, seed=seed, progress_bar=progress is not None)
    venv.close()
    if consistency_rounds:
        record["consistency"] = refine_prior(model, env_id, goal, consistency_rounds, consistency_steps,
                                             consistency_loop_uniform, n_envs, seed, progress,
                                             consistency_validation_episodes, consistency_expert_in_loops)
    entry = _add_model(zoo, model, goal, env_id, record, command, replace)
    return record_evaluations(zoo, entry, episodes) if episodes else (entry, {})


def refine_prior(model: ACER, env_id: str, goal: str, rounds: int, steps: int, loop_uniform: float = 0.5,
                 n_envs: int = 4, seed: int = 0, progress: Optional[Callable[[str], None]] = None,
                 validation_episodes: int = 0, expert_in_loops: bool = False) -> dict[str, Any]:
    """
    The greedy-consistency phase (:func:`~sb3_disagree.finish.consistency.greedy_consistency`, three epochs a round)
    on a trained prior, in place, on env seeds ``seed + CONSISTENCY_SEED_OFFSET``, apart from its training, its
    validation and its card's; in a loop it draws from ``(1 - loop_uniform) pi + loop_uniform / n``.

    :param validation_episodes: With > 0, each fit is validated greedily after every epoch over this many episodes
        from DAgger's validation starts (env seed ``PRIOR_VALIDATION_SEED``, the env's own step limit) and keeps its
        best epoch, and the phase ends on the best round's weights (ties: the later round), as DAgger keeps its
        best round; 0: the last epoch of the last round
    :param expert_in_loops: Label every visit of a pose an episode visits more than once with the env's expert
        (``expert_action()``), in failed episodes too; the loop-free paths of successes label the other steps
    :return: The phase's record for the card: its settings, seconds and per-round statistics
    """
    from sb3_disagree.finish.consistency import greedy_consistency
    from sb3_disagree.defaults import CONSISTENCY_SEED_OFFSET

    net, best, done = model.policy.acting_net, None, 0

    def on_round(stats: Any) -> None:
        nonlocal best, done
        done += 1
        line = (f"consistency round: {stats.successes}/{stats.episodes} episodes reached the goal, "
                f"{stats.labels} labels{f' ({stats.expert_labels} from the expert)' if expert_in_loops else ''}, "
                f"accuracy {stats.accuracy:.3f}")
        if stats.validation:
            kept = stats.validation[stats.epoch - 1]
            line += f", validation success {kept:.2f} (epoch {stats.epoch})"
            if best is None or kept >= best[0]:
                best = (kept, done, {k: v.clone() for k, v in net.state_dict().items()})
        if progress:
            progress(line)

    validate = None
    if validation_episodes > 0:
        validation_env = make_vec(env_id, goal, n_envs=n_envs, seed=PRIOR_VALIDATION_SEED)

        def validate() -> tuple[float, float]:
            validation_env.seed(PRIOR_VALIDATION_SEED)  # the same starts at every validation
            result = evaluate(model, validation_env, validation_episodes, deterministic=True)
            return result.success_rate, result.mean_length

    env = make_vec(env_id, goal, n_envs=n_envs, seed=seed + CONSISTENCY_SEED_OFFSET)
    start = time.perf_counter()
    try:
        history = greedy_consistency(model, env, rounds, steps, seed=seed, on_round=on_round, loop_uniform=loop_uniform,
                                     validate=validate, expert_in_loops=expert_in_loops)
    finally:
        env.close()
        if validate is not None:
            validation_env.close()
    record = {"rounds": rounds, "steps_per_round": steps, "loop_uniform": loop_uniform,
              **({"expert_in_loops": True} if expert_in_loops else {})}
    if best is not None:
        net.load_state_dict(best[2])
        record.update(validation_episodes=validation_episodes, validation_seed=PRIOR_VALIDATION_SEED,
                      selected_round=best[1])
        if progress:
            progress(f"kept consistency round {best[1]} (validation success {best[0]:.2f})")
    model.policy.sync_averages()  # the average network follows the fitted one, as after DAgger
    return {**record, "seconds": round(time.perf_counter() - start, 1), "per_round": [r.as_dict() for r in history]}


def refine_entry(zoo: Any, goal: str, env_id: str, rounds: int, steps: int = 20_000, loop_uniform: float = 0.5,
                 n_envs: int = 4, seed: int = 0, episodes: int = 100, only_if_better: bool = False, command: str = "",
                 progress: Optional[Callable[[str], None]] = None,
                 validation_episodes: int = 0, expert_in_loops: bool = False) -> tuple[Any, dict[str, Evaluation], bool]:
    """
    The greedy-consistency phase (:func:`refine_prior`) on a prior already in the zoo, which it replaces: the card keeps
    how the prior was trained, adds the phase (with the evaluations it replaces, under ``before``), and records the
    refined prior's evaluation alone anew. With the seed of the prior's training this is the second half of
    ``make_prior(..., consistency_rounds=rounds)``, for a prior whose training stopped after DAgger or that loops
    greedily. What ``dopt priors refine`` does.

    :param zoo: The :class:`~sb3_disagree.priors.zoo.Zoo`
    :param goal: The prior's goal
    :param env_id: Its environment
    :param rounds: Rounds of the phase (>= 1)
    :param steps: Env steps per round
    :param loop_uniform: In a loop, the phase draws from ``(1 - u) pi + u / n``
    :param n_envs: Parallel envs
    :param seed: Seed of the phase (env seeds ``seed + CONSISTENCY_SEED_OFFSET``)
    :param episodes: Evaluation episodes each way for the card (0: none, and the card's old evaluations are dropped)
    :param only_if_better: Replace the prior only if the refined one is better alone: the lower of its greedy and
        sampled success over ``episodes`` from the card's env seeds above the card's (which must have both, over
        as many episodes); else the zoo is left as it was. A phase can lower a prior (a greedy policy's success is
        a fragile function of its weights), and the prior it would replace is otherwise lost
    :param command: The command that refined it, added to the card's command
    :param progress: Called with a line of text after each round
    :param validation_episodes: Greedy validation episodes after each epoch, from DAgger's validation starts: each
        round keeps its best epoch and the phase its best round (0: none; :func:`refine_prior`)
    :param expert_in_loops: Label every visit of a pose an episode visits more than once with the env's expert, in
        failed episodes too (:func:`refine_prior`)
    :return: The zoo entry (as read back), the refined prior's evaluations by label ("greedy", "sampled"), and
        whether it replaced the prior
    """
    from sb3_disagree.defaults import PRIOR_CARD_SEED

    zoo.check_writable()  # before any training
    if rounds < 1 or steps < n_envs or not 0 <= loop_uniform <= 1 or episodes < 0 or validation_episodes < 0:
        raise ValueError(f"--rounds must be >= 1, --steps >= {n_envs} (one per env), --loop-uniform in [0, 1], "
                         f"--episodes >= 0 and --validation-episodes >= 0, got {rounds}, {steps}, {loop_uniform}, "
                         f"{episodes} and {validation_episodes}")
    entry = zoo.get(goal, env_id)
    model = zoo.load(entry, device="auto")  # refuses an entry with a problem
    if not isinstance(model, ACER):
        raise ValueError(f"the greedy-consistency phase refines an ACER prior, and {goal!r} is {type(model).__name__}")
    before = {"greedy": entry.card.evaluation_greedy, "sampled": entry.card.evaluation}
    comparable = episodes > 0 and all(ev and ev.get("episodes") == episodes and ev.get("seed") == PRIOR_CARD_SEED
                                      for ev in before.values())
    if only_if_better and not comparable:
        raise ValueError(f"--only-if-better compares with the card's greedy and sampled evaluations over --episodes "
                         f"({episodes}) from seed {PRIOR_CARD_SEED}, and {goal!r}'s card has no such pair: run "
                         f"dopt priors eval {goal} --episodes {episodes} --record first, or change --episodes")
    record = dict(entry.card.training or {})
    phase = refine_prior(model, env_id, goal, rounds, steps, loop_uniform, n_envs, seed, progress, validation_episodes,
                         expert_in_loops)
    evaluations = {label: _evaluate_model(lambda _: model, entry, episodes, label == "greedy", PRIOR_CARD_SEED)
                   for label in ("greedy", "sampled")} if episodes else {}
    if only_if_better and (min(ev.success_rate for ev in evaluations.values())
                           <= min(ev["success_rate"] for ev in before.values())):
        return entry, evaluations, False
    phase["before"] = {label: ev for label, ev in before.items() if ev}  # the card's evaluations it replaces
    if "consistency" in record:  # a second phase: kept apart, in order
        record["consistency_more"] = [*record.get("consistency_more", []), phase]
    else:
        record["consistency"] = phase
    made_by = "; then ".join(c for c in (entry.card.command, command) if c)
    entry = _add_model(zoo, model, goal, env_id, record, made_by, replace=True, env_kwargs=entry.card.env_kwargs)
    for evaluation in evaluations.values():  # of these very weights, from the card's env seeds
        entry = zoo.record_evaluation(entry, {**evaluation.as_dict(), "seed": PRIOR_CARD_SEED})
    return entry, evaluations, True


def _add_model(zoo: Any, model: BaseAlgorithm, goal: str, env_id: str, training: dict[str, Any], command: str,
               replace: bool, env_kwargs: Optional[dict[str, Any]] = None) -> Any:
    """Save a trained model into the zoo with its card (through a temporary file: the zoo copies it atomically)."""
    with tempfile.TemporaryDirectory() as tmp:
        model.save(Path(tmp) / "model.zip")
        return zoo.add(Path(tmp) / "model.zip", goal, env_id, env_kwargs=env_kwargs, training=training,
                       command=command, replace=replace)


def record_evaluations(zoo: Any, entry: Any, episodes: int,
                       progress: Optional[Callable[[str, int], None]] = None) -> tuple[Any, dict[str, Evaluation]]:
    """
    Evaluate a zoo entry alone greedy and sampled (env seeds from ``PRIOR_CARD_SEED``) and record both on its card.

    :param progress: Called with the label and the number of finished episodes
    :return: The entry as read back, and the evaluations by label ("greedy", "sampled")
    """
    from sb3_disagree.defaults import PRIOR_CARD_SEED

    evaluations = {}
    for label in ("greedy", "sampled"):
        evaluations[label] = evaluate_entry(zoo, entry, episodes, label == "greedy", PRIOR_CARD_SEED,
                                            (lambda n, label=label: progress(label, n)) if progress else None)
        entry = zoo.record_evaluation(entry, {**evaluations[label].as_dict(), "seed": PRIOR_CARD_SEED})
    return entry, evaluations


def add_prior(zoo: Any, model_path: Any, env_id: str, goal: Optional[str] = None, episodes: int = 100,
              replace: bool = False, command: str = "", progress: Optional[Callable[[str, int], None]] = None,
              trust: bool = False) -> tuple[Any, dict[str, Evaluation]]:
    """
    Add a saved SB3 model to the zoo and record its evaluation alone (greedy and sampled) on its card: what
    ``dopt priors add`` does. A model card beside the model (as ``dopt train`` writes) gives the goal and how
    the model was trained. The file is opened without unpickling what it carries (``sb3_disagree.loading``); one
    that needs that is refused unless ``trust``.

    :param zoo: The :class:`~sb3_disagree.priors.zoo.Zoo`
    :param model_path: The model file
    :param env_id: Its environment
    :param goal: The goal it reaches (default: the goal on its model card)
    :param episodes: Evaluation episodes each way for the card (0: none)
    :param replace: Replace an existing prior for this goal
    :param command: The command that added it, for the card
    :param progress: Called with the label and the number of finished episodes
    :param trust: Open the file as SB3 does, unpickling what it carries (a file you made or trust)
    :return: The zoo entry (as read back) and the evaluations by label
    """
    from sb3_disagree.model_card import CARD_NAME, read_model_card

    zoo.check_writable()

    model_path = Path(model_path)
    if not model_path.exists():
        raise FileNotFoundError(f"{model_path} does not exist")
    run = read_model_card(model_path.parent / CARD_NAME).get("sb3_disagree") or {}
    if goal is None:
        if not run.get("goal"):
            raise ValueError(f"--goal is needed: no model card with a goal beside {model_path}")
        goal = str(run["goal"])
    if run.get("env_id") and run["env_id"] != env_id:
        raise ValueError(f"the model card beside {model_path} says it was trained in {run['env_id']}, not {env_id}; "
                         f"pass --env {run['env_id']}")
    made = {"model_card": {k: run.get(k) for k in ("mode", "steps", "seed", "command", "priors")}} if run else {}
    entry = zoo.add(model_path, goal, env_id, training={"method": "external", **made}, command=command, replace=replace,
                    trust=trust)
    return record_evaluations(zoo, entry, episodes, progress) if episodes else (entry, {})
