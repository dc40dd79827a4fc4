"""Figures: similarity heatmaps and training curves."""

from collections.abc import Sequence
from pathlib import Path
from typing import Optional, Union

import numpy as np


def similarity_heatmap(matrix: np.ndarray, labels: Sequence[str], out: Union[str, Path], title: str = "",
                       reference: Optional[np.ndarray] = None, reference_title: str = "paper") -> None:
    """
    Draw a cosine-similarity matrix (and, beside it, a reference matrix) as annotated heatmaps.

    :param matrix: Square matrix of similarities
    :param labels: Row and column labels
    :param out: PNG path
    :param title: Title of the matrix
    :param reference: Optional matrix of the same labels to draw beside it
    :param reference_title: Title of the reference
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mats = [(matrix, title)] + ([(reference, reference_title)] if reference is not None else [])
    n = len(labels)
    fig, axes = plt.subplots(1, len(mats), figsize=(0.62 * n * len(mats) + 1.5, 0.55 * n + 1.2), squeeze=False)
    for ax, (m, t) in zip(axes[0], mats):
        im = ax.imshow(m, cmap="viridis", vmin=0, vmax=1)
        ax.set_xticks(range(n), labels, rotation=60, ha="right", fontsize=8)
        ax.set_yticks(range(n), labels, fontsize=8)
        for i in range(n):
            for j in range(n):
                ax.text(j, i, f"{m[i, j]:.2f}", ha="center", va="center", fontsize=6,
                        color="white" if m[i, j] < 0.6 else "black")
        ax.set_title(t, fontsize=9)
    fig.colorbar(im, ax=axes[0].tolist(), shrink=0.8)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    plt.close(fig)
