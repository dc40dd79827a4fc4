"""
Rewrite a zoo's ACER priors without the average networks' copies of ``net``, as ``ACER.save`` now writes them.

Each ``model.zip`` keeps every member byte for byte except ``policy.pth``, which loses the ``average_net.*`` and
``ema_net.*`` entries equal to ``net``'s (:func:`sb3_disagree.acer.policies.compact_averages`); the card's sha256
follows. Before a file is replaced, the new bytes loaded by ``ACER.load`` must give the original tensors, entry
for entry, so the policies that load are the same.

    python benchmarks/compact_zoo.py zoo/default zoo/greedy
"""

import argparse
import io
import json
import zipfile
from pathlib import Path

import torch as th

from sb3_disagree import ACER
from sb3_disagree.acer.policies import compact_averages
from sb3_disagree.files import write_atomic
from sb3_disagree.priors.zoo import sha256_of


def compact(model_path: Path) -> tuple[int, int]:
    """
    Compact one prior's ``policy.pth`` in place and point its card at the new file.

    :param model_path: A zoo entry's ``model.zip`` (its ``card.json`` beside it)
    :return: The file's size before and after, in bytes
    """
    before = model_path.stat().st_size
    with zipfile.ZipFile(model_path) as archive:
        members = [(info, archive.read(info.filename)) for info in archive.infolist()]
    policy = next(data for info, data in members if info.filename == "policy.pth")
    full = th.load(io.BytesIO(policy), map_location="cpu", weights_only=True)
    small = compact_averages(full)
    if len(small) == len(full):
        return before, before
    buffer = io.BytesIO()
    th.save(small, buffer)
    out = io.BytesIO()
    with zipfile.ZipFile(out, mode="w") as archive:
        for info, data in members:
            archive.writestr(info, buffer.getvalue() if info.filename == "policy.pth" else data)
    loaded = ACER.load(io.BytesIO(out.getvalue()), device="cpu").policy.state_dict()
    if list(loaded) != list(full) or not all(th.equal(full[k], v) for k, v in loaded.items()):
        raise SystemExit(f"{model_path}: the compacted file does not load to the original tensors")
    write_atomic(model_path, out.getvalue())
    card_path = model_path.with_name("card.json")
    card = json.loads(card_path.read_text())
    card["sha256"] = sha256_of(model_path)
    write_atomic(card_path, json.dumps(card, indent=2) + "\n")
    return before, model_path.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("zoos", nargs="+", type=Path, help="zoo folders (ENV_DIR/GOAL/model.zip inside)")
    args = parser.parse_args()
    total = [0, 0]
    for zoo in args.zoos:
        for model_path in sorted(zoo.glob("*/*/model.zip")):
            before, after = compact(model_path)
            total[0] += before
            total[1] += after
            print(f"{model_path}: {before / 1e6:.2f} MB -> {after / 1e6:.2f} MB")
    print(f"total: {total[0] / 1e6:.1f} MB -> {total[1] / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
