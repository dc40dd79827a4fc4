"""
The shipped zoo as a table in docs/zoo.md, read from the cards (goal, method, steps, success, size).

    python benchmarks/zoo_table.py
"""

from docs_section import write_section

from sb3_disagree.zoo import Zoo


def main() -> None:
    zoo = Zoo()
    rows, total = [], 0
    for e in zoo.entries():
        size = e.model_path.stat().st_size if e.model_path.exists() else 0
        total += size
        card = e.card
        if card is None:
            rows.append(f"| {e.goal} | {e.env_id} | - | - | - | - | - | {e.problem} |")
            continue
        ev, tr = card.evaluation, card.training
        episodes = ev.get("episodes", 0)
        # Successes out of episodes: 0.947 must not read as 0.95 against a 0.95 bar.
        success = f"{ev['success_rate']:.3f} ({round(ev['success_rate'] * episodes)}/{episodes})" if episodes else "-"
        rows.append(
            f"| {e.goal} | {e.env_id} | {tr.get('method', '?')} | {tr.get('steps', '?')} | {success} | "
            f"{ev.get('mean_length', float('nan')):.1f} | "
            f"{size / 1e6:.1f} MB | {'ok' if not e.problem else e.problem} |"
        )
    body = (
        "Read from the cards by `python benchmarks/zoo_table.py`. Success: the prior alone from its env's "
        "start distribution (the apartment: random corridor poses; the office: random poses anywhere on the "
        "floor), actions sampled from its distribution as the method follows priors, over the episodes on "
        "the card (env seeds 10000+). Each card keeps the command that made the prior.\n\n"
        "| goal | env | method | labelled steps | success | mean length | size | status |\n"
        "|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + f"\n\nTotal size: {total / 1e6:.1f} MB.\n"
    )
    write_section("zoo-table", "The shipped zoo", body, page="zoo.md")
    print(body)


if __name__ == "__main__":
    main()
