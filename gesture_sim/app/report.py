"""The evaluation report: ``report.json``, ``table.md`` and its figures (bars, speed
histograms, timelines) for a :class:`~gesture_sim.app.evaluation.EvalResult`.

The numbers are :mod:`gesture_sim.app.evaluation`'s; this module only writes and draws them
(plots live in the app layer, so that the metrics never import it).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from gesture_sim.app.evaluation import (
    PIPELINE_METHODS,
    TABLE_METRICS,
    EvalResult,
    coupling_verdicts,
    format_table,
    format_verdicts,
)
from gesture_sim.metrics import motion as mm
from gesture_sim.metrics.points import EVAL_FPS, HAND_POINTS, POINT_NAMES

#: The files of every report (besides ``timelines/``), relative to its folder.
REPORT_FILES = ("report.json", "table.md", "bars.png", "velocity_hist.png")


def write_report(result: EvalResult, folder: str | os.PathLike[str], command: str = "",
                 timelines: bool = True) -> list[Path]:
    """Write ``report.json``, ``table.md``, ``bars.png``, ``velocity_hist.png`` and
    ``timelines/<audio>_<method>.png`` (pipeline methods, first seed) plus
    ``timelines/<audio>_compare.png`` (hand speed of every method against the speech).

    All or nothing: the files are drawn into a staging folder and published into ``folder``
    together at the end (:func:`gesture_sim.fileio.atomic_folder`), so a failure or a signal
    leaves a previous report as it was. Returns the paths written (in ``folder``)."""
    from gesture_sim.fileio import atomic_folder

    folder = Path(folder)
    with atomic_folder(folder) as stage:
        written = write_report_files(result, stage, command=command, timelines=timelines)
    return [folder / p.relative_to(stage) for p in written]


def write_report_files(result: EvalResult, folder: str | os.PathLike[str], command: str = "",
                       timelines: bool = True) -> list[Path]:
    """:func:`write_report`'s files, written straight into ``folder`` (each atomically, but
    one after the other): for a staging folder of :func:`gesture_sim.fileio.atomic_folder`,
    such as the one ``eval --report`` holds while its workers draw the timelines."""
    from gesture_sim.fileio import atomic_path

    folder = Path(folder)
    (folder / "timelines").mkdir(parents=True, exist_ok=True)
    written = []
    data = result.to_dict()
    data["command"] = command
    path = folder / "report.json"
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(data, indent=1))
    written.append(path)
    path = folder / "table.md"
    text = "# Motion evaluation\n\n"
    if command:
        text += f"```\n{command}\n```\n\n"
    text += (f"Seeds: {', '.join(map(str, result.seeds))}; inputs: "
             f"{', '.join(i['name'] for i in result.inputs)}. Cells: mean ± sd over seeds and "
             "files [mean over files of the sd over seeds]. ↑ higher is better, ↓ lower, "
             "≈mocap closer to the real co-speech motion (last column) is better.\n\n")
    text += format_table(result) + "\n"
    verdicts = data.get("verdicts", {})
    if verdicts:
        text += ("\nDoes the motion follow the speech? Margin over random selection and over "
                 "mismatched audio (✓: larger than the seed spread):\n\n```\n"
                 + format_verdicts(result_verdicts(result)) + "\n```\n")
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)
    written.append(path)
    written.append(plot_bars(result, folder / "bars.png"))
    written.append(plot_velocity_hist(result, folder / "velocity_hist.png"))
    if timelines:
        written += plot_timelines(result, folder / "timelines")
    return written


def result_verdicts(result: EvalResult) -> dict:
    """The coupling verdicts of a result (:func:`coupling_verdicts`)."""
    return coupling_verdicts(result.summary())


_COLOURS = {"controller": "tab:blue", "levine09": "tab:orange", "random": "tab:gray",
            "real": "tab:green", "mismatched": "tab:red"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    from gesture_sim.fileio import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    _plt().close(fig)
    return path


def plot_bars(result: EvalResult, path: Path) -> Path:
    """One panel per table metric: a bar per method (mean) with error bars (sd over seeds and
    files) and the seed spread as a thick inner bar; the real mocap figure as a dashed line."""
    plt = _plt()
    summ = result.summary()
    methods = [m for m in result.methods if m in summ]
    keys = [(k, lab) for k, lab, _ in TABLE_METRICS if any(k in summ[m] for m in methods)]
    cols = 5
    rows = max(1, math.ceil(len(keys) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False)
    for ax, (k, lab) in zip(axes.ravel(), keys, strict=False):
        x = np.arange(len(methods))
        mean = [summ[m].get(k, {}).get("mean", np.nan) for m in methods]
        sd = [summ[m].get(k, {}).get("sd", np.nan) for m in methods]
        ssd = [summ[m].get(k, {}).get("seed_sd", np.nan) for m in methods]
        ax.bar(x, np.nan_to_num(mean), color=[_COLOURS.get(m, "k") for m in methods], alpha=0.8)
        ax.errorbar(x, np.nan_to_num(mean), yerr=np.nan_to_num(sd), fmt="none", ecolor="k",
                    capsize=3, lw=1)
        ax.errorbar(x, np.nan_to_num(mean), yerr=np.nan_to_num(ssd), fmt="none", ecolor="k",
                    lw=3)
        if k in result.reference:
            ax.axhline(result.reference[k], color="tab:green", ls="--", lw=1)
        ax.set_xticks(x)
        ax.set_xticklabels(methods, rotation=30, fontsize=7)
        ax.set_title(lab, fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(keys):]:
        ax.axis("off")
    fig.suptitle("Motion metrics per method (thin bars: sd over seeds and files; thick: seed "
                 "spread; dashed: real co-speech mocap)", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_velocity_hist(result: EvalResult, path: Path, bins: int = 60) -> Path:
    """Speed histograms (density) of the hands and of the head per method (seed 0 runs, all
    files) against the real co-speech motion of the library."""
    plt = _plt()
    groups = (("hands", [POINT_NAMES.index(j) for j in HAND_POINTS]),
              ("elbows", [POINT_NAMES.index(j) for j in ("left_elbow", "right_elbow")]),
              ("head", [POINT_NAMES.index("head")]))
    fig, axes = plt.subplots(1, len(groups), figsize=(5 * len(groups), 3.6))
    ev_ref = (np.concatenate(result.reference_positions) if result.reference_positions
              else None)
    for ax, (name, idx) in zip(axes, groups, strict=True):
        speeds: dict[str, np.ndarray] = {}
        for m in result.methods:
            if m == "mismatched":
                continue
            parts = [mm.joint_speeds(r.positions, EVAL_FPS)[:, idx].ravel()
                     for (a, meth), r in result.runs.items() if meth == m]
            if parts:
                speeds[m] = np.concatenate(parts)
        if ev_ref is not None:
            speeds["real mocap (library)"] = mm.joint_speeds(ev_ref, EVAL_FPS)[:, idx].ravel()
        top = max((np.percentile(v, 99.5) for v in speeds.values() if len(v)), default=1.0)
        edges = np.linspace(0, top, bins + 1)
        for m, v in speeds.items():
            ax.hist(v, edges, density=True, histtype="step", lw=1.4,
                    color=_COLOURS.get(m, "k"), label=m,
                    ls="--" if m.startswith("real mocap") else "-")
        ax.set_title(f"{name} speed", fontsize=10)
        ax.set_xlabel("m/s")
        ax.set_yscale("log")
    axes[0].set_ylabel("density")
    axes[-1].legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def plot_timelines(result: EvalResult, folder: Path) -> list[Path]:
    """The pipeline's timeline figure per (audio, pipeline method) for the first seed, and a
    stacked comparison per audio: intensity and onsets, then each method's hand speed."""
    from gesture_sim.app.render import timeline_data
    from gesture_sim.app.timeline import plot_timeline

    plt = _plt()
    out = []
    for (audio, method), run in sorted(result.runs.items()):
        if run.run is not None and method in PIPELINE_METHODS:
            p = folder / f"{audio}_{method}.png"
            plot_timeline(timeline_data(run.run, title=f"{audio} — {method}"), p)
            out.append(p)
    for inp in result.inputs:
        audio = inp["name"]
        mine = [(m, result.runs[(audio, m)]) for m in result.methods
                if (audio, m) in result.runs and m != "mismatched"]
        if not mine:
            continue
        run0 = next((r.run for _, r in mine if r.run is not None), None)
        fig, axes = plt.subplots(len(mine) + 1, 1, figsize=(14, 1.4 * (len(mine) + 1) + 0.6),
                                 sharex=True)
        if run0 is not None:
            samples = np.asarray(run0.audio, dtype=float)
            inten = mm.intensity_envelope(samples)
            onsets = mm.detect_onsets(samples)
            t = np.arange(len(inten)) * mm.FRAME_STEP_S
            axes[0].plot(t, inten, color="0.3", lw=0.7)
            for o in onsets:
                axes[0].axvline(o, color="tab:red", lw=0.4, alpha=0.6)
            axes[0].set_ylim(max(inten.max() - 60, -80), inten.max() + 3)
        axes[0].set_ylabel("dB / onsets", fontsize=8)
        axes[0].set_title(f"{audio}: speech intensity and onsets, hand speed per method",
                          fontsize=10, loc="left")
        hands = [POINT_NAMES.index(j) for j in HAND_POINTS]
        for ax, (m, r) in zip(axes[1:], mine, strict=True):
            s = mm.joint_speeds(r.positions, EVAL_FPS)[:, hands].mean(axis=1)
            ax.plot(np.arange(len(s)) / EVAL_FPS, s, color=_COLOURS.get(m, "k"), lw=0.8)
            if r.switch_frames is not None:
                for f in r.switch_frames:
                    ax.axvline(f / EVAL_FPS, color="0.6", lw=0.4)
            ax.set_ylabel(f"{m}\nm/s", fontsize=8)
        axes[-1].set_xlabel("time (s)")
        fig.tight_layout()
        p = folder / f"{audio}_compare.png"
        out.append(_save(fig, p))
    return out
