"""``dopt train`` and ``dopt eval``: the method on the command line, with a live display."""

import json
import time
from pathlib import Path
from typing import Optional

import typer
from rich.live import Live
from rich.table import Table
from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.cli.common import DEFAULT_ENV, clean_errors, command_line, console


class LiveDisplay(BaseCallback):
    """Steps, env steps/s, recent success rate, prior usage and disagreement, refreshed every second."""

    def __init__(self, live: Live) -> None:
        super().__init__()
        self.total, self.live, self.last_draw, self.t0, self.n0 = 0, live, 0.0, time.perf_counter(), 0

    def _on_training_start(self) -> None:
        # learn() has made its budget absolute by now, also when a run resumes (as SB3's progress bar reads it).
        self.total = int(self.locals["total_timesteps"])
        self.t0, self.n0 = time.perf_counter(), self.model.num_timesteps

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if now - self.last_draw >= 1.0:
            self.last_draw = now
            self.live.update(self.table(now))
        return True

    def table(self, now: float) -> Table:
        m = self.model
        behaviour = getattr(m, "behaviour", None)
        stats = getattr(behaviour, "last", {}) if behaviour is not None else {}
        success = m.ep_success_buffer
        t = Table(show_header=False, box=None)
        t.add_row("steps", f"{m.num_timesteps:,} / {self.total:,}")
        t.add_row("env steps/s", f"{(m.num_timesteps - self.n0) / max(now - self.t0, 1e-9):.0f}")
        t.add_row("success (last 100 episodes)", f"{sum(success) / len(success):.2f}" if success else "-")
        t.add_row("prior usage", f"{stats['prior/usage']:.2f}" if "prior/usage" in stats else "-")
        t.add_row("disagreement", f"{stats['prior/disagreement']:.3f}" if "prior/disagreement" in stats else "-")
        return t


def train(
    goal: str = typer.Option(..., "--goal", help="The new goal word."),
    env: str = typer.Option(DEFAULT_ENV, "--env", help="Gymnasium id of the environment."),
    mode: str = typer.Option("disagreement", "--mode", help="disagreement, room-sensor, scratch, finetune (start "
                             "from the nearest prior), kickstart (distil the priors), jsrl (Jump-Start RL) or ppo (SB3's PPO)."),
    priors: str = typer.Option("auto", "--priors", help="auto (by similarity), or goals: a,b"),
    alpha: int = typer.Option(10, "--alpha", help="Disagreement window."),
    beta: float = typer.Option(0.1, "--beta", help="Follow priors while the window's mean disagreement is below this."),
    steps: Optional[int] = typer.Option(None, "--steps", help="Env steps [default: 100000]; with --resume, the "
                                        "run's new total (default: its saved one)."),
    seed: int = typer.Option(0, "--seed"),
    n_envs: int = typer.Option(4, "--n-envs"),
    embedding: Optional[Path] = typer.Option(None, "--embedding", help="Word vectors file (default: MiniLM)."),
    zoo: Optional[Path] = typer.Option(None, "--zoo", help="Zoo folder (default: the shipped zoo)."),
    eval_every: int = typer.Option(0, "--eval-every", help="Evaluate the new policy alone every this many env "
                                   "steps (0: never); logged as eval/success_rate."),
    eval_episodes: int = typer.Option(20, "--eval-episodes", help="Episodes per evaluation."),
    vec_env: str = typer.Option("dummy", "--vec-env", help="dummy (envs in this process) or subproc (one process "
                                "per env)."),
    overlap: bool = typer.Option(True, "--overlap/--no-overlap", help="Replay updates in a second thread while "
                                 "the next segment is collected (faster on two cores); --no-overlap for the "
                                 "sequential loop the experiments use."),
    frame_stack: int = typer.Option(1, "--frame-stack", help="The new policy sees its last this many observations "
                                    "(its memory); the priors keep one."),
    record_trajectories: bool = typer.Option(False, "--record-trajectories", help="Write env 0's episodes to "
                                             "trajectories.jsonl (for dopt eval --trajectory)."),
    init: str = typer.Option("scratch", "--init", help="scratch (a fresh network) or prior (the nearest prior's "
                             "weights, as finetune; with any mode that has priors)."),
    jsrl_horizon: int = typer.Option(0, "--jsrl-horizon", help="jsrl: the guide's first horizon in steps (0: the "
                                     "priors' mean episode length on their cards)."),
    out: Path = typer.Option(Path("runs"), "--out", help="Root folder of the runs."),
    card_episodes: int = typer.Option(20, "--card-episodes", help="Episodes each way (greedy, sampled) of the "
                                      "evaluation on the model card written beside model.zip (0: none)."),
    progress_every: float = typer.Option(30.0, "--progress-every", help="Seconds between progress lines when the "
                                         "output is not a terminal."),
    resume: Optional[Path] = typer.Option(None, "--resume", help="A run folder to continue (from its newest "
                                          "complete checkpoint)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing run in the same folder."),
    checkpoint_every: int = typer.Option(25_000, "--checkpoint-every", help="Env steps between checkpoints (model, "
                                         "replay buffer, log positions; 0: only at the end)."),
) -> None:
    """Train a policy for a new goal with disagreement options (or the room sensor, or from scratch)."""
    with clean_errors():
        from sb3_disagree.run import RunConfig, train as run, write_card

        config = RunConfig(goal=goal, env_id=env, mode=mode,
                           priors="auto" if priors == "auto" else [p.strip() for p in priors.split(",") if p.strip()],
                           alpha=alpha, beta=beta, steps=100_000 if steps is None else steps, seed=seed, n_envs=n_envs,
                           eval_every=eval_every, eval_episodes=eval_episodes, vec_env=vec_env, overlap=overlap,
                           frame_stack=frame_stack, jsrl_horizon=jsrl_horizon, init=init,
                           record_trajectories=record_trajectories, checkpoint_every=checkpoint_every,
                           embedding=str(embedding) if embedding else None, zoo=str(zoo) if zoo else None)
        if resume is None:
            config.validate()
        else:
            _refuse_ignored_flags(config, resume, force)

        def show_priors(names, sims):
            console.print("priors: " + ", ".join(f"[bold]{n}[/] (similarity {s:.3f})" for n, s in zip(names, sims)))

        kwargs = dict(resume=resume, on_priors=show_priors, steps=steps if resume is not None else None, force=force)
        if console.is_terminal:
            with Live(console=console, refresh_per_second=2, transient=False) as live:
                display = LiveDisplay(live)
                run_dir, model, finished = run(config, out, callbacks=[display], **kwargs)
                live.update(display.table(time.perf_counter()))
        else:  # a log file, a pipe, a batch scheduler: plain lines at a fixed interval
            from sb3_disagree.callbacks import ProgressLines

            run_dir, model, finished = run(config, out, callbacks=[ProgressLines(progress_every)], **kwargs)
        if card_episodes and finished:
            console.print(f"evaluating the new policy alone for its card ({card_episodes} episodes each way)")
        evaluations = write_card(run_dir, model, card_episodes if finished else 0, command_line())
        for label, result in evaluations.items():
            console.print(f"the new policy alone, {label}: success {result.success_rate:.2f}, mean length "
                          f"{result.mean_length:.1f} over {result.episodes} episodes")
        if (run_dir / "evaluations.npz").exists():
            import numpy as np

            evals = np.load(run_dir / "evaluations.npz")
            console.print("the new policy alone (success): " + ", ".join(
                f"{t:,} steps {np.mean(s):.2f}" for t, s in zip(evals["timesteps"], evals["successes"])))
        if finished:
            console.print(f"done: {model.num_timesteps:,} steps; wrote {run_dir}")
        else:
            console.print(f"[yellow]interrupted[/] at {model.num_timesteps:,} steps; saved the model and replay buffer "
                          f"in {run_dir}; continue with: dopt train --goal {goal} --resume {run_dir}")
            raise typer.Exit(code=130)


def _refuse_ignored_flags(config, resume: Path, force: bool) -> None:
    """A resumed run keeps its saved settings: a flag that would change one is an error, not silently dropped."""
    import yaml
    from dataclasses import fields

    from sb3_disagree.run import RunConfig

    if force:
        raise ValueError("--force replaces a run and --resume continues one: choose one")
    saved_path = Path(resume) / "config.yaml"
    if not saved_path.exists():
        raise FileNotFoundError(f"{resume} is not a run folder with config.yaml and model.zip to resume")
    saved = yaml.safe_load(saved_path.read_text())
    if saved.get("goal") != config.goal:
        raise ValueError(f"{resume} trains the goal {saved.get('goal')!r}, not {config.goal!r}")
    defaults = RunConfig(goal=config.goal)
    # The loop (--overlap) is the saved one whatever the flag; --steps is the new budget.
    given = [f.name for f in fields(RunConfig) if f.name not in ("goal", "steps", "overlap", "acer_kwargs")
             and getattr(config, f.name) != getattr(defaults, f.name)]
    if given:
        flags = ", ".join({"env_id": "--env"}.get(name, "--" + name.replace("_", "-")) for name in given)
        raise ValueError(f"--resume continues {resume} with its saved settings; drop {flags}")


def eval_run(
    run_or_model: Path = typer.Argument(..., help="A run folder or a model.zip."),
    episodes: int = typer.Option(100, "--episodes"),
    deterministic: Optional[bool] = typer.Option(None, "--deterministic/--stochastic", help="Only greedy or only "
                                                 "sampled actions [default: both, side by side]."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Env seed of the first evaluation env [default: the "
                                       "run's seed + 20000, as the run's own final evaluation]."),
    trajectory: Optional[Path] = typer.Option(None, "--trajectory", help="Draw the run's recorded episodes (PNG)."),
    episode: int = typer.Option(-1, "--episode", help="Which recorded episode to draw (-1: the last)."),
) -> None:
    """Evaluate the new policy alone (no priors): success rate, episode length, return."""
    with clean_errors():
        import yaml

        from sb3_disagree.run import algorithm_of, evaluate_both

        path = Path(run_or_model)
        run_dir = path if path.is_dir() else path.parent
        model_path = path / "model.zip" if path.is_dir() else path
        if not model_path.exists():
            raise FileNotFoundError(f"no model at {model_path}")
        cfg_path = run_dir / "config.yaml"
        if not cfg_path.exists():
            raise FileNotFoundError(f"{cfg_path} is missing: it names the environment and goal to evaluate in")
        cfg = yaml.safe_load(cfg_path.read_text())
        algorithm = algorithm_of(cfg.get("mode", "disagreement"))
        try:
            model = algorithm.load(model_path, device="cpu")
        except Exception as exc:  # a damaged file, or another algorithm's
            raise ValueError(f"{model_path} could not be loaded as {algorithm.__name__}: {exc}") from None
        labels = ("greedy", "sampled") if deterministic is None else ("greedy" if deterministic else "sampled",)
        for label, result in evaluate_both(model, cfg, episodes, seed, labels).items():
            console.print(f"{cfg['goal']}: success {result.success_rate:.2f}, mean length {result.mean_length:.1f}, "
                          f"mean return {result.mean_return:.2f} over {episodes} episodes "
                          f"({label} actions, no priors)")
        if trajectory is not None:
            draw_recorded(run_dir, cfg, trajectory, episode)


def draw_recorded(run_dir: Path, cfg: dict, out: Path, episode: int = -1) -> None:
    """Draw one recorded training episode on the map, each step coloured by whether it followed a prior."""
    from sb3_disagree.envs.apartment import ApartmentEnv
    from sb3_disagree.envs.topdown import draw_trajectory

    path = run_dir / "trajectories.jsonl"
    lines = path.read_text().splitlines() if path.exists() else []
    if not lines:
        raise FileNotFoundError(f"{run_dir} has no recorded episodes (trajectories.jsonl): train with "
                                "--record-trajectories to record them")
    try:
        record = json.loads(lines[episode])
    except IndexError:
        raise ValueError(f"--episode {episode}: the run recorded {len(lines)} episodes") from None
    layout = ApartmentEnv(goal=cfg["goal"], obs="state").layout
    # positions[i] is where step i ended; the segment from i to i + 1 is step i + 1's action.
    tags = record["tags"][1:]
    draw_trajectory(layout, record["positions"], tags, goal=cfg["goal"], out=out)
    console.print(f"wrote {out}: the episode at {record['timesteps']:,} steps, "
                  f"{'success' if record['success'] else 'no success'}, {tags.count('prior')} of {len(tags)} steps on priors")
