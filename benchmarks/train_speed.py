"""
End-to-end training throughput on the apartment RGB: `dopt train` with disagreement options (and from
scratch) against SB3's PPO CnnPolicy on the same env, one after another in the same process, each for
the same number of env steps after its own warm-up; written into docs/benchmarks.md.

    python benchmarks/train_speed.py --steps 6000 [--threads 2] [--vec-env dummy subproc] [--write]
"""

import argparse
import os
import platform
import time
from pathlib import Path
from tempfile import TemporaryDirectory

import torch as th
from stable_baselines3.common.callbacks import BaseCallback


class Rate(BaseCallback):
    """Env steps per second after the first ``skip`` steps (env creation, model set-up and warm-up excluded)."""

    def __init__(self, skip: int) -> None:
        super().__init__()
        self.skip, self.t0, self.n0 = skip, None, 0

    def _on_step(self) -> bool:
        if self.t0 is None and self.num_timesteps >= self.skip:
            self.t0, self.n0 = time.perf_counter(), self.num_timesteps
        return True

    def rate(self) -> float:
        return (self.num_timesteps - self.n0) / (time.perf_counter() - self.t0)


def acer_rate(mode: str, steps: int, warm: int, vec_env: str) -> float:
    from sb3_disagree.training import RunConfig, train

    with TemporaryDirectory() as tmp:
        rate = Rate(warm)
        config = RunConfig(goal="bathtub", mode=mode, priors=["shower", "toilet"], steps=warm + steps, vec_env=vec_env)
        train(config, Path(tmp), callbacks=[rate])
        return rate.rate()


def ppo_rate(steps: int, warm: int, vec_env: str) -> float:
    from stable_baselines3 import PPO

    from sb3_disagree.training import RunConfig, build_env

    env = build_env(RunConfig(goal="bathtub", vec_env=vec_env), None)  # the envs dopt train makes
    # rl-zoo3's Atari settings for PPO, with 4 envs.
    model = PPO("CnnPolicy", env, n_steps=128, n_epochs=4, batch_size=256, learning_rate=2.5e-4, clip_range=0.1,
                ent_coef=0.01, vf_coef=0.5, seed=0)
    rate = Rate(warm)
    model.learn(warm + steps, callback=rate)
    env.close()
    return rate.rate()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=6_000)
    parser.add_argument("--warm", type=int, default=2_400, help="steps before timing (ACER's replay starts at 2k)")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--vec-env", nargs="+", default=["dummy", "subproc"])
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    rows = []
    for vec_env in args.vec_env:
        d = acer_rate("disagreement", args.steps, args.warm, vec_env)
        s = acer_rate("scratch", args.steps, args.warm, vec_env)
        p = ppo_rate(args.steps, args.warm, vec_env)
        rows.append(f"| {vec_env} | {d:.0f} | {s:.0f} | {p:.0f} |")
        print(rows[-1], flush=True)
    body = (f"Command: `python benchmarks/train_speed.py --steps {args.steps} --threads {args.threads} --vec-env "
            f"{' '.join(args.vec_env)}`; {platform.machine()}, {os.cpu_count()} cores, {args.threads} torch threads, "
            f"one run at a time on a quiet machine. Env steps/s over {args.steps} steps after a {args.warm}-step warm-up "
            "(ACER's replay updates have started), apartment RGB 60x80, 4 envs; ACER with the defaults of "
            "`dopt train`, PPO CnnPolicy with rl-zoo3's Atari settings (n_steps 128, 4 epochs, batch 256).\n\n"
            "| envs | dopt train, disagreement | dopt train, scratch | SB3 PPO CnnPolicy |\n|---|---|---|---|\n"
            + "\n".join(rows) + "\n")
    if args.write:
        from docs_section import write_section

        write_section("train-speed", "Training throughput: dopt train against PPO", body)
    print(body)


if __name__ == "__main__":
    main()
