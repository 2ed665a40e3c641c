"""The figures of bench/latency/paper.py, like the paper's: Fig. 5 (eps_j per request), Fig. 6
(eps_b per request, every series), Fig. 7 (frame times around the request with the largest
eps_b of each series) and Fig. 8 (tau_w per request)."""

from __future__ import annotations

import os

from bench.latency.experiment import Experiment, by_series, label
from bench.shared import common

POLICY_COLOR = {"paper": "tab:red", "ours": "tab:blue"}
PATH_STYLE = {"network": "-", "local": "--"}


def figures(records: list[dict], exp: Experiment, series: list[tuple[str, str]], out: str, subtitle: str) -> list[str]:
    """Writes the four figures into ``out``; one panel (or line) per (policy, path) series."""
    plt = common.pyplot()
    by = by_series(records, series)
    paths = []

    def save(fig, name):
        fig.suptitle(subtitle, fontsize=9)
        fig.tight_layout()
        path = os.path.join(out, name)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)

    # Fig. 5: eps_j per request
    fig, axes = per_camera_panels(plt, exp, series, by, "eps_ms", "eps_")
    for ax, ser in zip(axes[:, 0], series):
        for y in (-exp.period_ms / 2, exp.period_ms / 2):
            ax.axhline(y, color="grey", ls=":", lw=0.8)
        ax.axhline(0, color="black", lw=0.5)
        ax.set_title(f"{label(ser)}: eps_j = t* - t_j (signed); dotted: +/- tau_ia/2", fontsize=10)
        ax.set_ylabel("ms")
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("request")
    save(fig, "latency_fig5_eps.png")

    # Fig. 6: eps_b per request, every series; full scale and zoomed
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    for ax, zoom in zip(axes, (False, True)):
        for ser in series:
            ax.plot(
                [r["k"] for r in by[ser]],
                [r["eps_b_ms"] for r in by[ser]],
                ".",
                ls=PATH_STYLE[ser[1]],
                lw=0.7,
                ms=4,
                color=POLICY_COLOR[ser[0]],
                label=f"{label(ser)} ({sum(r['spike'] for r in by[ser])} spikes)",
            )
        ax.axhline(
            exp.spike_threshold_ms,
            color="black",
            ls="--",
            lw=0.8,
            label=f"spike threshold {exp.spike_threshold_ms:.2f} ms",
        )
        ax.axhline(
            exp.min_allowed_skew_ms,
            color="grey",
            ls=":",
            lw=0.8,
            label=f"min allowed skew {exp.min_allowed_skew_ms:.2f} ms",
        )
        if zoom:
            ax.set_ylim(max(0.0, exp.min_allowed_skew_ms - 2.0), exp.spike_threshold_ms + 1.5)
            ax.set_title("eps_b, zoomed on the threshold", fontsize=10)
        else:
            ax.set_title("eps_b = max t_j - min t_j per request", fontsize=10)
        ax.set_xlabel("request")
        ax.set_ylabel("ms")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    save(fig, "latency_fig6_skew.png")

    # Fig. 7: frames around the request with the largest eps_b of each series
    fig, axes = plt.subplots(len(series), 1, figsize=(11, 1.2 + 1.1 * len(exp.names) * len(series)), squeeze=False)
    for ax, ser in zip(axes[:, 0], series):
        if not by[ser]:
            ax.set_axis_off()
            continue
        worst = max(by[ser], key=lambda r: r["eps_b_ms"])
        t_star = worst["t_star"]
        for j, cam in enumerate(exp.names):
            context = worst.get("context", {}).get(cam, [])
            xs = [common.ms(tc - t_star) for _, tc in context]
            ax.plot(xs, [j] * len(xs), "o", mfc="white", mec="grey", ms=8, label="stored frames" if j == 0 else None)
            for fid, tc in context:
                ax.annotate(
                    str(fid),
                    (common.ms(tc - t_star), j),
                    textcoords="offset points",
                    xytext=(0, 8),
                    ha="center",
                    fontsize=7,
                    color="grey",
                )
            chosen = worst["frames"][cam]["t_capture"]
            ax.plot(
                [common.ms(chosen - t_star)],
                [j],
                "o",
                color=POLICY_COLOR[ser[0]],
                ms=9,
                label="chosen frame" if j == 0 else None,
            )
        ax.axvline(0, color="purple", lw=1.5, label="t*")
        for x in (-exp.period_ms / 2, exp.period_ms / 2):
            ax.axvline(x, color="purple", ls=":", lw=0.8)
        ax.set_yticks(range(len(exp.names)), exp.names)
        ax.set_ylim(-0.7, len(exp.names) - 0.3)
        xs = [common.ms(tc - t_star) for frames in worst.get("context", {}).values() for _, tc in frames]
        xs += [common.ms(f["t_capture"] - t_star) for f in worst["frames"].values()]
        ax.set_xlim(min(xs + [-exp.period_ms]) - 8, max(xs + [exp.period_ms]) + 8)
        ax.set_xlabel("capture time - t*, ms (dotted: t* +/- tau_ia/2; numbers: frame ids)")
        ax.set_title(
            f"{label(ser)}: request {worst['k']} with the largest eps_b = {worst['eps_b_ms']:.2f} ms"
            + ("" if "context" in worst else " (neighbouring frames not fetched)"),
            fontsize=10,
        )
        ax.grid(axis="x", alpha=0.3)
        ax.legend(fontsize=8, loc="upper right", ncol=3)
    save(fig, "latency_fig7_spike.png")

    # Fig. 8: tau_w per request
    fig, axes = per_camera_panels(plt, exp, series, by, "tau_w_ms", "tau_w")
    for ax, ser in zip(axes[:, 0], series):
        waits = [w for r in by[ser] for w in r["tau_w_ms"].values()]
        if waits:
            ax.axhline(
                sum(waits) / len(waits), color="black", ls="--", lw=0.8, label=f"mean {sum(waits) / len(waits):.2f} ms"
            )
        ax.axhline(exp.period_ms / 8 + 1, color="grey", ls=":", lw=0.8, label="target tau_ia/8 + 1 ms")
        ax.set_title(f"{label(ser)}: tau_w = time the service waited for each camera", fontsize=10)
        ax.set_ylabel("ms")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("request")
    save(fig, "latency_fig8_wait.png")
    return paths


def per_camera_panels(plt, exp: Experiment, series: list, by: dict, key: str, name: str):
    """A panel per series, sharing their axes, with a line per camera of ``record[key][camera]``
    over the requests; returns the figure and its axes."""
    fig, axes = plt.subplots(len(series), 1, figsize=(11, 3.4 * len(series)), squeeze=False, sharex=True, sharey=True)
    for ax, ser in zip(axes[:, 0], series):
        for j, cam in enumerate(exp.names, 1):
            ax.plot(
                [r["k"] for r in by[ser]],
                [r[key][cam] for r in by[ser]],
                ".-",
                lw=0.7,
                ms=4,
                label=f"{name}{j} ({cam})",
            )
    return fig, axes
