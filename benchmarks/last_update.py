"""
What the last train call does to a finished run's policy (docs/results.md, "Against the alternatives").

``rerun RUN_DIR``: train the run again from its ``config.yaml`` (runs are deterministic given their configuration,
seed and one torch thread), keep the policy as it was at the last periodic evaluation, and compare it with the
final one: that the rerun ends equal to the saved model, the mean KL between the two on states the earlier policy
visits, how often their argmax differs, and both policies' success alone, greedy and sampled, from the final
evaluation's env seeds. About one run's time.

``survey``: over every finished run under benchmarks/results/experiments whose last periodic evaluation is at its
budget, the periodic evaluation (before the last train call, 20 episodes) against the final one (after it, 100).

    python benchmarks/last_update.py rerun benchmarks/results/experiments/peers-nightstand/finetune/seed-1
    python benchmarks/last_update.py survey
"""

import argparse
import json
import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch as th
import yaml
from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.acer import ACER
from sb3_disagree.options.disagreement import kl as divergence
from sb3_disagree.run import RunConfig, train
from sb3_disagree.run.envs import build_env
from sb3_disagree.run.evaluation import evaluate_both


class KeepAt(BaseCallback):
    """Save the model the first time the run reaches ``steps`` (the periodic evaluation's step)."""

    def __init__(self, steps: int, path: Path) -> None:
        super().__init__()
        self.steps, self.path, self.kept = steps, path, False

    def _on_step(self) -> bool:
        if not self.kept and self.num_timesteps >= self.steps:
            self.model.save(self.path)
            self.kept = True
        return True


def policy_change(before: ACER, after: ACER, config: RunConfig, steps: int = 400) -> dict[str, float]:
    """Mean and 95th-percentile KL(before || after), and the share of states whose argmax differs, on the
    states ``before`` visits acting sampled on 4 envs for ``steps`` steps each."""
    env = build_env(config, None, n_envs=4, seed=777, vec_env="dummy")
    obs, seen = env.reset(), []
    for _ in range(steps):
        seen.append(obs)
        obs = env.step(before.predict(obs, deterministic=False)[0])[0]
    env.close()
    states = before.policy.obs_to_tensor(np.concatenate(seen))[0]
    with th.no_grad():
        p, q = before.policy.action_probs(states), after.policy.action_probs(states)
    kl = divergence(p, q).numpy()
    return {"kl_mean": round(float(kl.mean()), 4), "kl_p95": round(float(np.percentile(kl, 95)), 4),
            "argmax_changed": round(float((p.argmax(1) != q.argmax(1)).float().mean()), 3),
            "probs_before": [round(float(v), 3) for v in p.mean(0)], "probs_after": [round(float(v), 3) for v in q.mean(0)]}


def rerun(run_dir: Path, episodes: int) -> None:
    th.set_num_threads(1)
    config = RunConfig.of_saved(yaml.safe_load((run_dir / "config.yaml").read_text()))
    with tempfile.TemporaryDirectory() as tmp:
        kept = Path(tmp) / "at-last-evaluation.zip"
        _, final, _ = train(config, run_dir=Path(tmp) / "run", force=True, callbacks=[KeepAt(config.steps, kept)])
        before = ACER.load(kept, device="cpu")
    original = ACER.load(run_dir / "model.zip", device="cpu").policy.state_dict()
    same = max((final.policy.state_dict()[k] - v).abs().max().item() for k, v in original.items())
    print(f"rerun's final weights vs the saved model's: largest difference {same}")
    print("the last train call:", policy_change(before, final, config))
    for name, model in (("at the last periodic evaluation", before), ("final", final)):
        both = evaluate_both(model, asdict(config), episodes)  # the final evaluation's env seeds
        print(f"{name}: success alone " + ", ".join(f"{label} {e.success_rate:.2f} (mean length {e.mean_length:.0f})"
                                                    for label, e in both.items()) + f", {episodes} episodes each")


def survey(root: Path) -> None:
    gaps: dict[str, list[float]] = {"sampled": [], "greedy": []}
    for result in sorted(root.glob("*/*/seed-*/result.json")):
        record, evaluations = json.loads(result.read_text()), result.parent / "evaluations.npz"
        if not evaluations.exists():
            continue
        with np.load(evaluations) as data:
            if data["timesteps"][-1] != record["steps"]:
                continue
            gaps["sampled"].append(data["successes"][-1].mean() - record["final_alone"]["success_rate"])
            if "successes_greedy" in data and "final_alone_greedy" in record:  # runs that measured both
                gaps["greedy"].append(data["successes_greedy"][-1].mean() - record["final_alone_greedy"]["success_rate"])
    for label, values in gaps.items():
        g = np.array(values)
        print(f"{label}, {len(g)} runs: periodic evaluation at the budget minus the final one: mean {g.mean():+.3f}, "
              f"sd {g.std():.3f}, standard error {g.std() / np.sqrt(len(g)):.3f}, higher in {np.mean(g > 0):.0%}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    one = commands.add_parser("rerun")
    one.add_argument("run_dir", type=Path)
    one.add_argument("--episodes", type=int, default=40)
    commands.add_parser("survey")
    args = parser.parse_args()
    if args.command == "rerun":
        rerun(args.run_dir, args.episodes)
    else:
        survey(Path(__file__).parent / "results" / "experiments")
