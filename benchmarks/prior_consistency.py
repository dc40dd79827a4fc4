"""
The greedy-consistency phase on a copy of a shipped apartment prior (the zoo is not touched): 3 rounds of 20k env
steps from env seed 30 000, then the refined prior alone over 300 episodes greedy and sampled from its card's env
seeds (10 000+); 9b0ec2d:docs/results.md, "Greedy consistency after training". The refined model and its numbers go to
OUT (default: prior-consistency/ in the current folder).

    python benchmarks/prior_consistency.py shower [--rounds 3] [--zoo ZOO] [--out prior-consistency]
"""

import argparse
import json
import time
from pathlib import Path

import torch as th

from sb3_disagree import ACER
from sb3_disagree.acer.consistency import greedy_consistency
from sb3_disagree.defaults import PRIOR_CARD_SEED
from sb3_disagree.envs.vec import make_vec
from sb3_disagree.evaluation import evaluate
from sb3_disagree.priors.zoo import DEFAULT_ZOO, env_dir_name

ENV = "sb3_disagree/Apartment-v0"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("goal")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("prior-consistency"))
    parser.add_argument("--loop-uniform", type=float, default=0.0, help="in a loop, the uniform share of the draw")
    parser.add_argument("--zoo", type=Path, default=DEFAULT_ZOO, help="the zoo the prior is copied from")
    args = parser.parse_args()
    th.set_num_threads(1)
    model = ACER.load(args.zoo / env_dir_name(ENV) / args.goal / "model.zip", device="cpu")
    env = make_vec(ENV, args.goal, n_envs=4, seed=30_000)
    start = time.perf_counter()
    greedy_consistency(model, env, rounds=args.rounds, steps=20_000, on_round=print,
                       loop_uniform=args.loop_uniform)
    result = {"seconds": round(time.perf_counter() - start)}
    for deterministic in (True, False):
        evaluation = evaluate(model, make_vec(ENV, args.goal, n_envs=4, seed=PRIOR_CARD_SEED), 300, deterministic)
        result["greedy" if deterministic else "sampled"] = evaluation.as_dict()
        print(args.goal, "greedy" if deterministic else "sampled", evaluation.success_rate, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    model.save(args.out / f"{args.goal}.zip")
    (args.out / f"{args.goal}.json").write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
