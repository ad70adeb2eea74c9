#!/usr/bin/python3
"""Plots of a `spml diagnose` output folder, per joint, written to DIR/plots/*.png:
  residuals.png  torque residual (measured - model) against time on the test split, model as
                 given and extended; long records are drawn as the min..max envelope of each of
                 at most 800 time bins (a 50 s log at 1 kHz is 50 000 points: drawn one by one
                 the two models hide each other) with the bin's RMS as a line
  states.png     measured positions and velocities
  unexplained.png (when report.json lists unexplained joints) each such joint's held-out
                 residual and the GP fitted to it against its most relevant input (unexplained.csv)
  rollouts.png   (when report.json has rollouts) open-loop rollouts under the measured torques:
                 the position error at the end of the horizon (s), model as given and extended,
                 in rad or m; a log axis when the errors lie a decade or more apart
  rollouts_trajectories.png (when DIR/rollouts.csv exists) a few of those windows over time, one
                 column each: per joint the measured position and the positions simulated by the
                 model as given and by the extended model, and below it simulated − measured
Reads DIR/series.csv, DIR/rollouts.csv and DIR/report.json (written by diagnose). Units come from each joint's
type in the model file report.json names (hinge: N·m, rad; slide/prismatic: N, m)."""
import csv
import json
import math
import os
import sys
import textwrap
import xml.etree.ElementTree as ET

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

MAX_BINS = 800
HINGE = {"torque": "N·m", "position": "rad", "velocity": "rad/s"}
SLIDE = {"torque": "N", "position": "m", "velocity": "m/s"}


def joint_units(model_path, joints):
    """{joint: HINGE or SLIDE} from the MJCF's `type` (default hinge) or a URDF's `prismatic`.
    A model that cannot be read gives hinge units."""
    units = {j: HINGE for j in joints}
    try:
        root = ET.parse(model_path).getroot()
    except (OSError, ET.ParseError, TypeError):
        return units
    for el in root.iter("joint"):
        name, kind = el.get("name"), el.get("type", "hinge")
        if name in units and kind in ("slide", "prismatic"):
            units[name] = SLIDE
    return units


def envelope(t, v, bins=MAX_BINS):
    """(bin centres, min, max, rms) of v over at most `bins` equal-count bins of t; the samples
    themselves when there are fewer."""
    t, v = np.asarray(t), np.asarray(v)
    if len(t) <= bins:
        return t, v, v, np.abs(v)
    edges = np.linspace(0, len(t), bins + 1).astype(int)
    parts = [(t[a:b].mean(), v[a:b].min(), v[a:b].max(), np.sqrt(np.mean(v[a:b] ** 2)))
             for a, b in zip(edges[:-1], edges[1:]) if b > a]
    return tuple(np.array(c) for c in zip(*parts))


def residual_figure(t, test, col, joints, units, out):
    fig, axes = plt.subplots(len(joints), 1, figsize=(10, 1.9 * len(joints) + 1.2), sharex=True, squeeze=False)
    binned = len(t) > MAX_BINS
    for ax, j in zip(axes[:, 0], joints):
        tau = np.array([float(r[col["tau:" + j]]) for r in test])
        for key, color, name in (("given", "tab:red", "model as given"), ("final", "tab:blue", "extended model")):
            res = tau - np.array([float(r[col[key + ":" + j]]) for r in test])
            tc, lo, hi, rms = envelope(t, res)
            if binned:
                ax.fill_between(tc, lo, hi, color=color, alpha=0.3, lw=0, label=f"{name}: min..max per bin")
                ax.plot(tc, rms, color=color, lw=0.8, label=f"{name}: RMS per bin")
            else:
                ax.plot(tc, lo, color=color, lw=0.7, label=name)
        ax.axhline(0, color="black", lw=0.5)
        ax.set_ylabel(f"{j} [{units[j]['torque']}]", fontsize=8)
        ax.grid(alpha=0.3)
    if binned:
        # Say what a reader sees is not the samples: how they were binned, and over what width.
        width = (t[-1] - t[0]) / MAX_BINS
        # Equal-count bins hold floor or ceil of len/bins samples: say both when they differ.
        lo_n, hi_n = len(t) // MAX_BINS, -(-len(t) // MAX_BINS)
        per_bin = f"{lo_n}" if lo_n == hi_n else f"{lo_n}-{hi_n}"
        title = (f"torque residual (measured − model) on the test split, binned by time: {MAX_BINS} bins of "
                 f"{per_bin} samples ({width:.3g} s) each, band = min..max, line = RMS per bin")
    else:
        title = "torque residual (measured − model) on the test split, every sample"
    axes[0, 0].set_title("\n".join(textwrap.wrap(title, 80)), fontsize=10)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "residuals.png"), dpi=110)
    plt.close(fig)


def states_figure(t, test, col, joints, units, out):
    fig, axes = plt.subplots(len(joints), 2, figsize=(10, 1.9 * len(joints) + 1.2), sharex=True, squeeze=False)
    for row, j in zip(axes, joints):
        row[0].plot(t, [float(r[col["q:" + j]]) for r in test], lw=0.7)
        row[1].plot(t, [float(r[col["qd:" + j]]) for r in test], lw=0.7, color="tab:green")
        row[0].set_ylabel(f"q:{j} [{units[j]['position']}]", fontsize=8)
        row[1].set_ylabel(f"qd:{j} [{units[j]['velocity']}]", fontsize=8)
        for ax in row:
            ax.grid(alpha=0.3)
    axes[0, 0].set_title("measured positions, test split", fontsize=10)
    axes[0, 1].set_title("velocities, test split", fontsize=10)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "states.png"), dpi=110)
    plt.close(fig)


def rollout_figure(report, units, out):
    """Position error at the end of the open-loop rollouts, per joint, before and after."""
    ro = report.get("rollout", {})
    before, after = ro.get("position_error_before"), ro.get("position_error_after")
    if not before or not after:
        return False
    joints = list(before)
    kinds = {units.get(j, HINGE)["position"] for j in joints}
    unit = kinds.pop() if len(kinds) == 1 else "rad or m (per joint type)"
    x = np.arange(len(joints))
    fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(joints) + 3), 4))
    drawn = []
    for shift, errors, color, name in ((-0.2, before, "tab:red", "model as given"), (0.2, after, "tab:blue", "extended model")):
        # a rollout that diverged has an infinite error (null in report.json): no bar, a mark
        values = [float(errors[j]) if errors.get(j) is not None else math.inf for j in joints]
        finite = [v if math.isfinite(v) else 0.0 for v in values]
        drawn += [v for v in finite if v > 0]
        ax.bar(x + shift, finite, 0.4, color=color, label=name)
        for k, v in enumerate(values):
            if not math.isfinite(v):   # at the foot of the axes, which a log axis does not have at 0
                ax.annotate("diverged", (x[k] + shift, 0.02), xycoords=ax.get_xaxis_transform(), rotation=90,
                            ha="center", va="bottom", fontsize=7)
    # Errors a decade or more apart (a joint the extension fixed, one it did not need): on a
    # linear axis the small ones are invisible slivers, so the axis is logarithmic.
    log = len(drawn) >= 2 and max(drawn) >= 10 * min(drawn)
    if log:
        ax.set_yscale("log")
        ax.set_ylim(min(drawn) / 3, max(drawn) * 3)
    ax.set_xticks(x)
    ax.set_xticklabels(joints, rotation=30 if len(joints) > 4 else 0, ha="right" if len(joints) > 4 else "center")
    ax.set_xlabel("joint")
    ax.set_ylabel(f"mean |position error| after {ro.get('horizon_s', 0):g} s [{unit}]" + (", log scale" if log else ""))
    ax.set_title("\n".join(textwrap.wrap(
        f"open-loop rollouts under the measured torques: {ro.get('windows', '?')} windows of "
        f"{ro.get('horizon_s', 0):g} s on '{ro.get('split', '?')}' (mean over windows of the |error| at the end)", 60)), fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "rollouts.png"), dpi=110)
    plt.close(fig)
    return True


def read_trajectories(path):
    """rollouts.csv as (joints, {window: {column: array}}), windows in file order."""
    with open(path) as f:
        rows = list(csv.reader(f))
    head = rows[0]
    joints = [name[2:] for name in head if name.startswith("q:")]
    windows = {}
    for r in rows[1:]:
        windows.setdefault(int(r[0]), []).append([float(v) for v in r[1:]])
    return joints, {w: {name: np.array(c) for name, c in zip(head[1:], zip(*v))} for w, v in windows.items()}


def trajectory_figure(folder, report, out):
    """A few rollout windows over time (DIR/rollouts.csv): per joint a row of positions - measured,
    simulated by the model as given, by the extended model - and a row of simulated − measured
    (the drift, which on the position scale is often thinner than a line), a column per window."""
    path = os.path.join(folder, "rollouts.csv")
    if not os.path.exists(path):
        return False
    joints, windows = read_trajectories(path)
    if not joints or not windows:
        return False
    units = joint_units(report.get("model"), joints)
    ro = report.get("rollout", {})
    height = 2.6 * len(joints) + 1.2
    fig, axes = plt.subplots(2 * len(joints), len(windows), figsize=(3.6 * len(windows) + 1, height), sharex="col", squeeze=False)
    for c, (w, v) in enumerate(windows.items()):
        t = v["t"] - v["t"][0]
        for k, j in enumerate(joints):
            unit = units[j]["position"]
            top, bottom = axes[2 * k, c], axes[2 * k + 1, c]
            top.plot(t, v["q:" + j], color="black", lw=1.2, label="measured")
            for key, color, name in (("given", "tab:red", "model as given"), ("extended", "tab:blue", "extended model")):
                top.plot(t, v[key + ":" + j], color=color, lw=0.9, ls="--", label=name)
                bottom.plot(t, v[key + ":" + j] - v["q:" + j], color=color, lw=0.9, label=name)
            bottom.axhline(0, color="black", lw=0.5)
            ends = [abs(v[key + ":" + j][-1] - v["q:" + j][-1]) for key in ("given", "extended")]
            bottom.set_title(f"|error| at the end: as given {ends[0]:.3g} {unit}, extended {ends[1]:.3g} {unit}", fontsize=7)
            top.set_ylabel(f"q:{j} [{unit}]", fontsize=8)
            bottom.set_ylabel(f"simulated − measured [{unit}]", fontsize=8)
            for ax in (top, bottom):
                ax.grid(alpha=0.3)
                ax.tick_params(labelsize=7)
        axes[0, c].set_title(f"window {w} (from t = {v['t'][0]:.4g} s)", fontsize=9)
        axes[-1, c].set_xlabel("time into the window [s]")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle("\n".join(textwrap.wrap(
        f"open-loop rollouts under the measured torques from measured states, {len(windows)} of "
        f"{ro.get('windows', '?')} windows on '{ro.get('split', '?')}' (the largest end error first)", 90)), fontsize=10)
    fig.tight_layout()
    # Many rows: tight_layout leaves the two-line suptitle (its top at 0.98) over the column
    # titles; both take about 0.65 in.
    fig.subplots_adjust(top=min(fig.subplotpars.top, 0.98 - 0.65 / height))
    fig.savefig(os.path.join(out, "rollouts_trajectories.png"), dpi=100)
    plt.close(fig)
    return True


def main(folder):
    with open(os.path.join(folder, "series.csv")) as f:
        rows = list(csv.reader(f))
    head, body = rows[0], rows[1:]
    col = {name: i for i, name in enumerate(head)}
    joints = [name[4:] for name in head if name.startswith("tau:")]
    test = [r for r in body if r[0] == "test"]
    t = np.array([float(r[col["t"]]) for r in test])
    report = {}
    if os.path.exists(os.path.join(folder, "report.json")):
        with open(os.path.join(folder, "report.json")) as f:
            report = json.load(f)
    units = joint_units(report.get("model"), joints)
    out = os.path.join(folder, "plots")
    os.makedirs(out, exist_ok=True)
    residual_figure(t, test, col, joints, units, out)
    states_figure(t, test, col, joints, units, out)
    rollout_figure(report, units, out)
    trajectory_figure(folder, report, out)
    unexplained_figure(folder, units, out)


def unexplained_figure(folder, units, out):
    """Issue #22: each joint diagnose reports as unexplained - its held-out residual and the GP's
    prediction against the most relevant input (DIR/unexplained.csv) - into plots/unexplained.png."""
    path = os.path.join(folder, "unexplained.csv")
    if not os.path.exists(path):
        return
    with open(path) as f:
        rows = list(csv.reader(f))[1:]
    joints = list(dict.fromkeys(r[0] for r in rows))
    if not joints:
        return
    fig, axes = plt.subplots(len(joints), 1, figsize=(7, 2.4 * len(joints) + 0.6), squeeze=False)
    for ax, j in zip(axes[:, 0], joints):
        mine = sorted((float(r[2]), float(r[3]), float(r[4])) for r in rows if r[0] == j)
        name = next(r[1] for r in rows if r[0] == j)
        ax.plot([m[0] for m in mine], [m[1] for m in mine], ".", ms=2, color="tab:gray", label="residual (test)")
        ax.plot([m[0] for m in mine], [m[2] for m in mine], ".", ms=2, color="tab:purple", label="GP on the residual")
        ax.set_xlabel(name)
        ax.set_ylabel(f"{j} [{units[j]['torque']}]" if j in units else j, fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].set_title("unexplained: final residual against its most relevant input")
    axes[0, 0].legend(loc="upper right", fontsize=8, markerscale=4)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "unexplained.png"), dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: diagnose_plots.py DIR")
    main(sys.argv[1])
