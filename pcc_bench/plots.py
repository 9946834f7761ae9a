"""Figures of the reproduction summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pcc_agent.io import atomic_save_figure
from pcc_bench.records import REFERENCE_METHODS
from pcc_bench.tables import noise_variance


def summary_bar_chart(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in rows if r["method"] not in REFERENCE_METHODS]
    if not rows:
        return
    labels = [f"{r['env'].split('/')[1]}\n{r['method']}\n{r['preset']}"
              + (f"\nnoise variance {noise_variance(r)}" if r["noise_std"] else "")
              for r in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(rows)), 4))
    ax.bar(
        x - 0.2,
        [r["mean_all"] for r in rows],
        0.4,
        yerr=[np.nan if r["se_all"] is None else r["se_all"] for r in rows],
        label="ours (all models)",
        capsize=3,
    )
    paper = [r["paper_all"][0] if r["paper_all"] else np.nan for r in rows]
    paper_se = [r["paper_all"][1] if r["paper_all"] else 0 for r in rows]
    ax.bar(x + 0.2, paper, 0.4, yerr=paper_se, label="paper (all models)", capsize=3)
    for xi, r in zip(x, rows):
        # The value above each of our bars: a row at 0 % is then a readable "0.0", not a gap.
        ax.text(xi - 0.2, r["mean_all"] + 1, f"{r['mean_all']:.1f}", ha="center",
                va="bottom", fontsize=7)
        if r["oracle_mean"] is not None:
            ax.hlines(r["oracle_mean"], xi - 0.45, xi + 0.45, colors="k", linestyles="--")
        if r.get("floor_mean"):  # a floor of 0 would only hide the axis
            ax.hlines(r["floor_mean"], xi - 0.45, xi + 0.45, colors="0.4", linestyles=":")
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("% of steps in goal")
    ax.set_ylim(0, 105)
    ax.set_title("Control from pixels (dashed: oracle on the true state; dotted: zero actions)")
    ax.legend()
    fig.tight_layout()
    atomic_save_figure(fig, path)
    plt.close(fig)
