"""
The saved policy's current weights against the moving averages a model.zip also holds, each alone: the trust
region's average network (``alpha`` 0.99 per update, every ACER model) and, where the run kept one
(``ema_decay``), the slow average that ``predict`` acts with. Does acting with an average make the greedy policy
steadier? Each finished run of an experiment's cell, greedy and sampled, with SB3's ``evaluate_policy`` from the
env seeds of the run's own final evaluation; the network ``predict`` acted with there is read from result.json.

    python benchmarks/average_policy.py alone-nightstand-200k-whole --cell kickstart-rs1-ema [--episodes 100]

The runs' models are not tracked; each measurement is kept in the experiment's tracked ``average-CELL.json``
and read from there where the model is gone, so the table regenerates from a clone.
"""

import argparse
import json
from pathlib import Path

import yaml

from sb3_disagree.experiments.spec import load_experiment

ROOT = Path(__file__).resolve().parent / "results" / "experiments"
NETS = ("latest", "average", "ema")  # the current weights, the trust region's average, the slow average


def evaluate_net(run_dir: Path, net: str, episodes: int) -> dict[str, dict[str, float]]:
    """One of the run's networks alone, greedy and sampled (success rate and mean episode length)."""
    import torch as th

    from sb3_disagree.acer import ACER
    from sb3_disagree.run.evaluation import evaluate_both

    th.set_num_threads(1)
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    model = ACER.load(run_dir / "model.zip", device="cpu")
    policy = model.policy
    source = {"latest": policy.net, "average": policy.average_net, "ema": policy.ema_net}[net]
    policy.acting_net.load_state_dict(source.state_dict())
    return {label: {"success_rate": e.success_rate, "mean_length": e.mean_length}
            for label, e in evaluate_both(model, config, episodes).items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("experiment")
    parser.add_argument("--cell", default="kickstart-rs1")
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    experiment = load_experiment(args.experiment)
    folder = ROOT / experiment.name
    runs = [r for r in experiment.runs() if r.cell == args.cell and r.finished(folder)]
    if not runs:
        raise SystemExit(f"no finished {args.cell} runs of {experiment.name}")
    kept_path = folder / f"average-{args.cell}.json"
    kept = json.loads(kept_path.read_text()) if kept_path.exists() else {}
    nets = [n for n in NETS if n != "ema" or experiment.cells[args.cell].get("acer", {}).get("ema_decay")]
    rows = []
    for run in runs:
        run_dir = run.folder(folder)
        result = json.loads((run_dir / "result.json").read_text())
        if result["final_alone"]["episodes"] != args.episodes:
            raise SystemExit(f"{run_dir}'s final evaluation has {result['final_alone']['episodes']} episodes, "
                             f"not {args.episodes}")
        acted = "ema" if "ema" in nets else "latest"
        seed = kept.setdefault(str(run.seed), {})
        seed[acted] = {"greedy": {k: result["final_alone_greedy"][k] for k in ("success_rate", "mean_length")},
                       "sampled": {k: result["final_alone"][k] for k in ("success_rate", "mean_length")},
                       "episodes": args.episodes}
        for net in nets:
            if seed.get(net, {}).get("episodes") != args.episodes:
                if not (run_dir / "model.zip").exists():
                    raise SystemExit(f"{run_dir} has no model.zip and {kept_path} no {args.episodes}-episode "
                                     f"evaluation of its {net} network")
                seed[net] = {"episodes": args.episodes, **evaluate_net(run_dir, net, args.episodes)}
                kept_path.write_text(json.dumps(kept, indent=2, sort_keys=True) + "\n")
        rows.append(f"| {run.seed} | " + " | ".join(
            f"{seed[n]['greedy']['success_rate']:.2f} / {seed[n]['sampled']['success_rate']:.2f} "
            f"({seed[n]['greedy']['mean_length']:.0f})" for n in nets) + " |")
        print(rows[-1], flush=True)
    kept_path.write_text(json.dumps(kept, indent=2, sort_keys=True) + "\n")
    print(f"\nCommand: `python benchmarks/average_policy.py {experiment.name} --cell {args.cell} --episodes "
          f"{args.episodes}`\n\n| seed | " + " | ".join(nets) + " |\n|---|" + "---|" * len(nets) + "\n"
          + "\n".join(rows) + f"\n\nEach: greedy / sampled success over {args.episodes} episodes each way (mean greedy "
          "episode length in steps).")


if __name__ == "__main__":
    main()
