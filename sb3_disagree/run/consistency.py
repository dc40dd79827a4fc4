"""The greedy-consistency phase on a finished run: its model refined, evaluated both ways, written inside its folder."""

import json
import shutil
import time
from pathlib import Path
from typing import Any, Callable, Optional

from sb3_disagree.acer import ACER
from sb3_disagree.finish.consistency import RoundStats, greedy_consistency
from sb3_disagree.defaults import CONSISTENCY_SEED_OFFSET, VALIDATION_MAX_STEPS, VALIDATION_SEED_OFFSET
from sb3_disagree.envs.vec import make_vec
from sb3_disagree.files import write_atomic
from sb3_disagree.run.evaluation import evaluate_alone, evaluate_both, load_run

FOLDER = "consistent"  # inside the run: model.zip and result.json of the refined policy


def consistency_env(config: dict[str, Any]) -> Any:
    """The phase's 4 envs: the run's task and env settings, on env seeds of their own (the run's seed +
    ``CONSISTENCY_SEED_OFFSET``), apart from its training and evaluation seeds."""
    return make_vec(config["env_id"], config["goal"], config.get("env_kwargs") or {}, n_envs=4,
                    seed=config.get("seed", 0) + CONSISTENCY_SEED_OFFSET)


def greedy_validation(model: Any, config: dict[str, Any], episodes: int) -> Callable[[], tuple[float, float]]:
    """
    The validation of the phase's fits: the model's greedy success and mean episode length over ``episodes``
    episodes of the run's task, from the same starts each time (fresh envs seeded from the run's seed +
    ``VALIDATION_SEED_OFFSET``, apart from its training, phase and evaluation seeds), each episode cut at
    ``VALIDATION_MAX_STEPS`` (a greedy success takes about 80 steps; a loop would cost 500 at each validation).
    """
    cut = {**config, "env_kwargs": {**(config.get("env_kwargs") or {}), "max_episode_steps": VALIDATION_MAX_STEPS}}
    seed = config.get("seed", 0) + VALIDATION_SEED_OFFSET

    def validate() -> tuple[float, float]:
        result = evaluate_alone(model, cut, episodes, True, seed)
        return result.success_rate, result.mean_length

    return validate


def refine_run(run_dir: Path, rounds: int = 3, steps: int = 20_000, epochs: int = 3, learning_rate: float = 3e-4,
               episodes: int = 100, force: bool = False, name: str = FOLDER,
               on_round: Optional[Callable[[RoundStats], None]] = None, sampling: str = "loops", trust: bool = False) -> dict[str, Any]:
    """
    Run the greedy-consistency phase (:func:`~sb3_disagree.finish.consistency.greedy_consistency`) on a finished
    ACER run's ``model.zip``, on env seeds of its own (the run's seed + ``CONSISTENCY_SEED_OFFSET``), and write the
    refined model and its evaluation alone (greedy and sampled, from the run's final-evaluation env seeds, as
    ``result.json`` and ``dopt eval``) to ``run_dir/<name>/`` (``consistent`` by default). The run's own files are not touched.

    :param run_dir: A run folder (``model.zip`` and ``config.yaml``)
    :param rounds: Collect-and-fit rounds
    :param steps: Env steps per round
    :param epochs: Passes over the labels per round
    :param learning_rate: Adam's step size
    :param episodes: Evaluation episodes each way (greedy, sampled) after the phase; 0: none
    :param force: Replace an earlier phase's folder
    :param name: The folder inside the run that the refined model goes to
    :param on_round: Called with each round's statistics
    :param sampling: Where the collection samples: "loops" (greedy elsewhere) or "always"
    :param trust: Open the run's model as SB3 does, unpickling what it carries (``load_run``)
    :return: The result written to ``consistent/result.json``
    """
    run_dir = Path(run_dir)
    out = run_dir / name
    if not name or Path(name).name != name or name in (".", ".."):
        raise ValueError(f"--name must be a plain folder name, got {name!r}")
    if out.exists() and not force:
        raise ValueError(f"{out} holds an earlier phase's model: replace it with --force")
    if rounds < 1 or epochs < 1 or steps < 4 or learning_rate <= 0 or episodes < 0:
        raise ValueError(f"--rounds and --epochs must be >= 1, --steps >= 4 (one per env), --learning-rate > 0 and "
                         f"--episodes >= 0, got {rounds}, {epochs}, {steps}, {learning_rate} and {episodes}")
    config, model = load_run(run_dir, trust)
    if not isinstance(model, ACER):
        raise ValueError("the greedy-consistency phase refines an ACER policy; this run trained PPO")
    env = consistency_env(config)
    start = time.perf_counter()
    try:
        history = greedy_consistency(model, env, rounds, steps, epochs, learning_rate, seed=config.get("seed", 0),
                                     on_round=on_round, sampling=sampling)
    finally:
        env.close()
    seconds = time.perf_counter() - start
    if out.exists():
        shutil.rmtree(out)
    out.mkdir()
    model.save(out / "model.zip")
    # dopt eval reads the env and goal beside the model
    (out / "config.yaml").write_text((run_dir / "config.yaml").read_text())
    evaluations = evaluate_both(model, config, episodes) if episodes > 0 else {}
    result = {"rounds": rounds, "steps_per_round": steps, "epochs": epochs, "learning_rate": learning_rate,
              "sampling": sampling,
              "env_steps": sum(r.env_steps for r in history), "seconds": round(seconds, 1),
              "per_round": [r.as_dict() for r in history],
              **{f"final_alone{'_greedy' if label == 'greedy' else ''}": e.as_dict() for label, e in evaluations.items()}}
    write_atomic(out / "result.json", json.dumps(result, indent=2) + "\n")
    return result
