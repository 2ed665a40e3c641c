"""What bench/compare/peers.py prints and draws: a table per scenario, the targets, the figure."""

from __future__ import annotations

import numpy as np

from bench.compare.ours import IPC, LATEST, LATEST_VIEW, LOCAL, LOCAL_VIEW, SCENARIOS, TCP, TIME
from bench.compare.rivals import COPY, IMZ, IMZ_1, IMZ_PER_IMAGE, MPQ, REUSED, ZMQ_FLOOR
from bench.shared import common
from bench.shared.interleave import HOT, median, ratio

ROWS = (TCP, IPC, LOCAL, LOCAL_VIEW, LATEST, LATEST_VIEW, TIME, IMZ, IMZ_PER_IMAGE, IMZ_1, ZMQ_FLOOR, MPQ, COPY, REUSED)
PLOTTED = tuple(r for r in ROWS if r != IMZ_PER_IMAGE)
TARGET_SCENARIO = "2x1360x1024"  # the targets are set for 2 cameras 1360x1024
COPY_LIMIT = 1.3  # local copy / the plain copy of the same frames
VIEW_LIMIT = 0.3  # local zero-copy tuple / the `time` round trip
LATEST_VIEW_LIMIT = 0.2  # local zero-copy latest / the `time` round trip
TCP_LIMIT_1 = 2.0  # tuple over tcp / imagezmq for ONE image
TCP_LIMIT_N = 1.2  # tuple over tcp / imagezmq carrying the same images
TARGETS = (  # (contender, reference, limit): median(contender) <= limit x median(reference)
    (LOCAL, COPY, COPY_LIMIT),
    (LOCAL_VIEW, TIME, VIEW_LIMIT),
    (LATEST, COPY, COPY_LIMIT),
    (LATEST_VIEW, TIME, LATEST_VIEW_LIMIT),
    (TCP, IMZ_1, TCP_LIMIT_1),
    (TCP, IMZ, TCP_LIMIT_N),
)


def scenario_table(scenario: str, results: dict, n_cams: int) -> str:
    refs = (COPY, REUSED, TIME, IMZ, IMZ_1)
    rows = []
    for name in ROWS:
        if name not in results:
            continue
        s, m = results[name]["summary_ms"], median(results, name)
        faults = results[name].get("minor_faults_median")
        rows.append(
            [
                name,
                s["n"],
                results[name]["failed"],
                s["median"],
                s["p99"],
                "-" if faults is None else f"{faults:.0f}",
                median(results, name, HOT),
                *(ratio(m, median(results, ref)) for ref in refs),
            ]
        )
    _, w, h = SCENARIOS[scenario]
    mb = n_cams * w * h / 1e6
    return common.table(
        [
            "contender",
            "ok",
            "failed",
            "median ms",
            "p99 ms",
            "faults",
            "hot ms",
            "x copy",
            "x reused",
            "x time",
            f"x imagezmq({n_cams})",
            "x imagezmq(1)",
        ],
        rows,
        title=f"{scenario}: {n_cams} cameras {w}x{h} mono8, {mb:.2f} MB per tuple",
        digits=3,
        separators=(7,),
    )


def targets(all_results: dict) -> list[dict]:
    """The issue's targets on scenario TARGET_SCENARIO, each with its numbers and a verdict
    (None: not measurable)."""
    res = all_results.get(TARGET_SCENARIO, {})
    out = []
    for name, ref, limit in TARGETS:
        value, reference = median(res, name), median(res, ref)
        hot_value, hot_reference = median(res, name, HOT), median(res, ref, HOT)
        r, hot = ratio(value, reference), ratio(hot_value, hot_reference)
        out.append(
            {
                "target": f"{name} <= {limit:g}x {ref}",
                "scenario": TARGET_SCENARIO,
                "contender": name,
                "reference": ref,
                "median_ms": value,
                "reference_ms": reference,
                "ratio": r,
                "limit": limit,
                "pass": None if r is None else r <= limit,
                "hot_median_ms": hot_value,
                "hot_reference_ms": hot_reference,
                "hot_ratio": hot,
                "hot_pass": None if hot is None else hot <= limit,
            }
        )
    return out


def targets_table(tlist: list[dict]) -> str:
    rows = [
        [
            t["contender"],
            t["median_ms"],
            t["reference"],
            t["reference_ms"],
            t["ratio"],
            f"<= {t['limit']:g}",
            common.verdict(t["pass"]),
            t.get("hot_median_ms"),
            t.get("hot_reference_ms"),
            t.get("hot_ratio"),
            common.verdict(t.get("hot_pass")),
        ]
        for t in tlist
    ]
    return common.table(
        ["target: median of", "ms", "over the median of", "ms", "ratio", "limit", "verdict"]
        + ["hot ms", "hot ref ms", "hot ratio", "hot verdict"],
        rows,
        digits=3,
        separators=(7,),
        title=f"targets ({TARGET_SCENARIO}, same run, interleaved)"
        + ("" if any(t["median_ms"] is not None for t in tlist) else f": scenario {TARGET_SCENARIO} not measured")
        + "; verdict: the interleaved medians (cold), as the issue's goals are set; hot: the hot loop's",
    )


def plot(all_results: dict, path: str, title: str) -> None:
    plt = common.pyplot()
    from matplotlib import ticker

    scenarios = list(all_results)
    names = [n for n in PLOTTED if any(n in r for r in all_results.values())]
    width = 0.8 / len(names)
    fig, ax = plt.subplots(figsize=(max(10, 5 * len(scenarios)), 6))
    colors = plt.get_cmap("tab20").colors
    labels, lowest, highest = [], float("inf"), 0.0
    for j, name in enumerate(names):
        xs, meds, ups = [], [], []
        for i, scenario in enumerate(scenarios):
            s = all_results[scenario].get(name, {}).get("summary_ms")
            if s and s["median"] is not None:
                xs.append(i + (j - (len(names) - 1) / 2) * width)
                meds.append(s["median"])
                ups.append(s["p99"] - s["median"])
        ax.bar(
            xs,
            meds,
            width * 0.92,
            color=colors[j % len(colors)],
            label=name,
            yerr=[np.zeros(len(ups)), ups],
            capsize=2,
            error_kw={"elinewidth": 0.8},
        )
        labels += [(x, m) for x, m in zip(xs, meds)]
        lowest, highest = min([lowest, *meds]), max([highest, *(m + u for m, u in zip(meds, ups))])
    ax.set_yscale("log")
    bottom = lowest / 3
    ax.set_ylim(bottom, highest * 8)  # room for the legend above the whiskers
    for x, m in labels:  # the median, written at the foot of its bar
        ax.text(
            x,
            bottom * 1.15,
            f"{m:.3g}",
            ha="center",
            va="bottom",
            rotation=90,
            fontsize=7,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
        )
    ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xticks(range(len(scenarios)))
    ax.set_xticklabels(
        [f"{s}\n({SCENARIOS[s][0]} cameras {SCENARIOS[s][1]}x{SCENARIOS[s][2]} mono8)" for s in scenarios]
    )
    ax.set_ylabel("ms per sample (log scale): bar = median, whisker = p99")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=4, loc="upper left")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
