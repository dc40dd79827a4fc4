"""
A model card beside every trained model, in the format of the Hugging Face SB3 integration: a
``README.md`` whose YAML header carries ``library_name``, tags and a ``model-index`` of measured results,
so that a run can be published with the ecosystem's usual tools. The header also carries what this
package knows of the run (goal, priors and their similarity, the mode, the command).
"""

from pathlib import Path
from typing import Any, Optional

import yaml

CARD_NAME = "README.md"
LICENSE = "mit"  # the package's licence, which a trained model's card carries unless its owner names another


def _metric(name: str, value: float, kind: str) -> dict[str, Any]:
    return {"type": kind, "value": round(float(value), 4), "name": name, "verified": False}


def model_card(config: dict[str, Any], algorithm: str, evaluations: Optional[dict[str, Any]] = None,
               command: str = "", license: str = LICENSE) -> str:
    """
    The card's text.

    :param config: The run's saved configuration (``config.yaml``: env, goal, mode, chosen priors, ...)
    :param algorithm: The algorithm's name (``ACER``, ``PPO``)
    :param evaluations: ``{"greedy": Evaluation, "sampled": Evaluation}`` of the policy alone, or None
    :param command: The command that trained it
    :param license: The model's licence, as the Hugging Face card's ``license`` field
    """
    env_id, goal = config["env_id"], config["goal"]
    metrics = []
    for label, result in (evaluations or {}).items():
        metrics += [_metric(f"success_rate ({label})", result.success_rate, "success_rate"),
                    _metric(f"mean_reward ({label})", result.mean_return, "mean_reward")]
    priors = [{"goal": p, "similarity": None if s is None else round(float(s), 4)}
              for p, s in zip(config.get("chosen_priors") or [], config.get("similarities") or [])]
    header = {
        "library_name": "stable-baselines3",
        "license": license,
        "tags": [env_id, "deep-reinforcement-learning", "reinforcement-learning", "stable-baselines3", "sb3-disagree"],
        "model-index": [{"name": algorithm, "results": [{
            "task": {"type": "reinforcement-learning", "name": "reinforcement-learning"},
            "dataset": {"name": env_id, "type": env_id},
            "metrics": metrics}]}],
        "sb3_disagree": {"env_id": env_id, "env_kwargs": dict(config.get("env_kwargs") or {}), "goal": goal,
                         "mode": config.get("mode"), "priors": priors, "steps": config.get("num_timesteps"),
                         "seed": config.get("seed"), "command": command,
                         "evaluation": {label: {**result.as_dict()} for label, result in (evaluations or {}).items()}},
    }
    lines = [f"# **{algorithm}** agent reaching the **{goal}** in **{env_id}**", "",
             f"A policy trained with sb3-disagree (mode `{config.get('mode')}`"
             + (f", priors {', '.join(p['goal'] for p in priors)}" if priors else "") + ").", ""]
    if evaluations:
        lines += ["The policy alone (no priors), SB3's `evaluate_policy` from env seeds the run never trained on:", "",
                  "| actions | success | mean return | episodes |", "|---|---|---|---|"]
        lines += [f"| {label} | {r.success_rate:.2f} | {r.mean_return:.2f} | {r.episodes} |"
                  for label, r in evaluations.items()]
        lines.append("")
    loader = "from sb3_disagree import ACER" if algorithm == "ACER" else f"from stable_baselines3 import {algorithm}"
    lines += ["## Usage", "", "```python", "import sb3_disagree  # registers the envs",
              "from stable_baselines3.common.env_util import make_vec_env",
              "from stable_baselines3.common.evaluation import evaluate_policy", loader, "",
              f"model = {algorithm}.load(\"model.zip\")",
              f"env = make_vec_env(\"{env_id}\", n_envs=4, seed=777, env_kwargs=dict(goal=\"{goal}\"))",
              "successes = []", "",
              "def count(local, _):", "    if local[\"done\"]:", "        successes.append(local[\"info\"][\"is_success\"])",
              "", "evaluate_policy(model, env, n_eval_episodes=100, callback=count)",
              "print(f\"success {sum(successes) / len(successes):.2f}\")", "```", ""]
    if command:
        lines += ["## Training", "", f"`{command}`", ""]
    return "---\n" + yaml.safe_dump(header, sort_keys=False) + "---\n\n" + "\n".join(lines)


def write_model_card(run_dir: Path, config: dict[str, Any], algorithm: str,
                     evaluations: Optional[dict[str, Any]] = None, command: str = "") -> Path:
    """Write the card as ``README.md`` beside ``model.zip`` in ``run_dir``; :return: its path."""
    path = Path(run_dir) / CARD_NAME
    path.write_text(model_card(config, algorithm, evaluations, command))
    return path


def read_model_card(path: Path) -> dict[str, Any]:
    """
    The YAML header of a card (``README.md``), or {} where there is none or it is not a card.

    :param path: The card's path
    """
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError):
        return {}
    if not text.startswith("---\n") or "\n---" not in text[4:]:
        return {}
    try:
        header = yaml.safe_load(text[4:text.index("\n---", 4)])
    except yaml.YAMLError:
        return {}
    return header if isinstance(header, dict) else {}
