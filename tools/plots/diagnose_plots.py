#!/usr/bin/python3
"""Plots of a `spml diagnose` output folder: residuals against time before/after, and the
measured states, per joint, and the residual of joints reported unexplained against their most
relevant input. Reads DIR/series.csv and DIR/unexplained.csv (written by diagnose), writes
DIR/plots/*.png."""
import csv
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(folder):
    with open(os.path.join(folder, "series.csv")) as f:
        rows = list(csv.reader(f))
    head, body = rows[0], rows[1:]
    col = {name: i for i, name in enumerate(head)}
    joints = [name[4:] for name in head if name.startswith("tau:")]
    test = [r for r in body if r[0] == "test"]
    t = [float(r[col["t"]]) for r in test]
    out = os.path.join(folder, "plots")
    os.makedirs(out, exist_ok=True)

    fig, axes = plt.subplots(len(joints), 1, figsize=(10, 1.8 * len(joints) + 1), sharex=True, squeeze=False)
    for ax, j in zip(axes[:, 0], joints):
        tau = [float(r[col["tau:" + j]]) for r in test]
        given = [a - float(r[col["given:" + j]]) for a, r in zip(tau, test)]
        final = [a - float(r[col["final:" + j]]) for a, r in zip(tau, test)]
        ax.plot(t, given, lw=0.7, color="tab:red", label="model as given")
        ax.plot(t, final, lw=0.7, color="tab:blue", label="extended model")
        ax.set_ylabel(j)
        ax.grid(alpha=0.3)
    axes[0, 0].set_title("torque residual (measured - model), test split")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "residuals.png"), dpi=90)
    plt.close(fig)

    fig, axes = plt.subplots(len(joints), 2, figsize=(10, 1.8 * len(joints) + 1), sharex=True, squeeze=False)
    for row, j in zip(axes, joints):
        row[0].plot(t, [float(r[col["q:" + j]]) for r in test], lw=0.7)
        row[1].plot(t, [float(r[col["qd:" + j]]) for r in test], lw=0.7, color="tab:green")
        row[0].set_ylabel("q " + j)
        row[1].set_ylabel("qd " + j)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "states.png"), dpi=90)
    plt.close(fig)
    unexplained(folder, out)


def unexplained(folder, out):
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
        ax.set_ylabel(j)
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
