"""
Can a trained policy's own successes teach a greedy-reliable one? Run a saved model sampled (its reliable
mode) from training env seeds, keep its successful episodes, cut every loop out of them (where a frame
repeats, the steps since its first visit are dropped and the last visit's action is kept: the one that left
the loop), fit a fresh policy with a stack of K frames to the actions that remain (cross-entropy), and
evaluate it alone, greedy and sampled, from the run's unseen env seeds (docs/results.md).

    python benchmarks/distill_successes.py RUN_DIR [--frames 8] [--episodes 200] [--epochs 10]
"""

import argparse
import hashlib
import time
from pathlib import Path

import numpy as np
import torch as th
import yaml

from sb3_disagree import ACER
from sb3_disagree.acer.memory import push_frames
from sb3_disagree.defaults import FINAL_EVAL_SEED_OFFSET
from sb3_disagree.envs.vec import make_vec
from sb3_disagree.priors.make import _fit as fit_labels
from sb3_disagree.run.evaluation import evaluate_alone

COLLECT_SEED_OFFSET = 5_000  # training-side env seeds, apart from the run's own and its evaluations'


def successes(model: ACER, env, n: int) -> tuple[list[list[tuple[np.ndarray, int]]], int]:
    """``n`` successful episodes of the sampled policy, as (channel-first observation, action) lists, and the tries."""
    obs, state, starts = env.reset(), None, np.ones(env.num_envs, bool)
    current: list[list] = [[] for _ in range(env.num_envs)]
    kept, tried = [], 0
    while len(kept) < n:
        actions, state = model.predict(obs, state, starts, deterministic=False)
        for i in range(env.num_envs):
            current[i].append((np.transpose(obs[i], (2, 0, 1)), int(actions[i])))
        obs, _, starts, infos = env.step(actions)
        for i in np.flatnonzero(starts):
            tried += 1
            if infos[i].get("is_success"):
                kept.append(current[i])
            current[i] = []
    return kept[:n], tried


def without_loops(episode: list[tuple[np.ndarray, int]]) -> list[tuple[np.ndarray, int]]:
    """The episode with every stretch between two visits of the same frame removed (the later visit kept)."""
    def key(frame: np.ndarray) -> str:
        return hashlib.sha1(frame.tobytes()).hexdigest()

    out: list[tuple[np.ndarray, int]] = []
    where: dict[str, int] = {}
    for frame, action in episode:
        if key(frame) in where:
            first = where[key(frame)]
            for dropped, _ in out[first:]:
                del where[key(dropped)]
            out = out[:first]
        where[key(frame)] = len(out)
        out.append((frame, action))
    return out


def fit(student: ACER, x: np.ndarray, y: np.ndarray, epochs: int, seed: int) -> float:
    """Cross-entropy on (stack, action) pairs, the learning rate annealed to zero; the last epoch's accuracy."""
    policy, rng = student.policy, np.random.default_rng(seed)
    optimizer = th.optim.Adam(policy.net.parameters(), lr=1e-3)
    schedule = th.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=epochs)
    accuracy = 0.0
    for _ in range(epochs):
        _, accuracy = fit_labels(policy, optimizer, x, y, 1, 128, rng)  # DAgger's own fitting step
        schedule.step()
    return accuracy


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--episodes", type=int, default=200, help="successful episodes to learn from")
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--eval-episodes", type=int, default=100)
    args = parser.parse_args()
    th.set_num_threads(1)
    config = yaml.safe_load((args.run_dir / "config.yaml").read_text())
    th.manual_seed(config["seed"])
    teacher = ACER.load(args.run_dir / "model.zip", device="cpu")
    env = make_vec(config["env_id"], config["goal"], config.get("env_kwargs") or {}, n_envs=4,
                   seed=config["seed"] + COLLECT_SEED_OFFSET)
    start = time.perf_counter()
    episodes, tried = successes(teacher, env, args.episodes)
    cut = [without_loops(e) for e in episodes]
    print(f"{len(episodes)} successes in {tried} episodes; mean length {np.mean([len(e) for e in episodes]):.1f}, "
          f"{np.mean([len(e) for e in cut]):.1f} without loops ({time.perf_counter() - start:.0f} s)")
    xs, ys = [], []
    for episode in cut:
        stack = None
        for t, (frame, action) in enumerate(episode):
            stack = push_frames(stack, frame[None], np.array([t == 0]), args.frames)
            xs.append(stack[0])
            ys.append(action)
    student = ACER("CnnPolicy", env, seed=config["seed"], policy_kwargs=dict(frame_stack=args.frames))
    accuracy = fit(student, np.stack(xs), np.asarray(ys), args.epochs, config["seed"])
    print(f"fitted {len(ys)} actions, {args.frames} frames: accuracy {accuracy:.3f} ({time.perf_counter() - start:.0f} s)")
    env.close()
    for deterministic in (True, False):
        e = evaluate_alone(student, config, args.eval_episodes, deterministic, config["seed"] + FINAL_EVAL_SEED_OFFSET)
        print(f"student alone, {'greedy' if deterministic else 'sampled'}: success {e.success_rate:.2f} over "
              f"{e.episodes} episodes, mean length {e.mean_length:.1f}")
