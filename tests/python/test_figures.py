#!/usr/bin/python3
"""Checks every figure spml draws: each axes that holds data has both axis labels, and its x
data are what the x label says (time stamps, the first input, learners, joints).

  test_figures.py PLOTS_DIR BENCH_DIR... : BENCH_DIR holds results.csv and predictions.h5 of a
  `spml bench` run; the figures are drawn here by importing the scripts (PLOTS_DIR), with
  savefig captured, and a synthetic diagnose folder is made for diagnose_plots.py.
Exit 0 when every check passes; prints one line per figure."""
import csv
import json
import math
import os
import sys
import tempfile

import h5py
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, sys.argv[1])
import bench_plots  # noqa: E402
import diagnose_plots  # noqa: E402

FAILURES = []
FIGURES = {}


def check(ok, what):
    if not ok:
        FAILURES.append(what)


def capture(fig, out, name, written):
    FIGURES[name] = fig
    written.append(name)


def labelled(fig, name):
    for ax in fig.axes:
        if not (ax.lines or ax.collections or ax.patches):
            continue
        shared_x = ax.get_shared_x_axes().get_siblings(ax)
        xlabel = ax.get_xlabel() or next((a.get_xlabel() for a in shared_x if a.get_xlabel()), "")
        check(xlabel != "", f"{name}: an axes without an x label")
        check(ax.get_ylabel() != "", f"{name}: an axes without a y label")


def bench_figures(bench):
    published = os.path.join(os.path.dirname(os.path.abspath(sys.argv[1])), "..", "data", "published")
    if not os.path.exists(os.path.join(published, "tables.csv")):
        published = os.environ["SPML_PUBLISHED"]
    rows = bench_plots.read_results(os.path.join(bench, "results.csv"))
    FIGURES.clear()
    bench_plots.table_figures(rows, published, "", [])
    bench_plots.prediction_figures(os.path.join(bench, "predictions.h5"), rows, [], 2.0, "", [])
    with h5py.File(os.path.join(bench, "predictions.h5"), "r") as p:
        data = h5py.File(p.attrs["data"], "r")
        outputs = p.attrs.get("outputs", "").split(",") if "outputs" in p.attrs else None
        for name, fig in FIGURES.items():
            labelled(fig, name)
            kind, split = name.split("_")[0], "_".join(name.split("_")[2:-1])
            ax = fig.axes[0] if kind != "pred" else fig.axes[-1]
            if kind == "table":
                algos = [t.get_text() for t in fig.axes[0].get_xticklabels()]
                check(fig.axes[0].get_xlabel() == "learner" and {r["algo"] for r in rows if r["split"] == split} <= set(algos),
                      f"{name}: x ticks are not the learners: {algos}")
                lo, hi = fig.axes[0].get_ylim()
                shown = [v for v in fig.axes[0].get_yticks() if lo <= v <= hi]
                check(len(shown) >= 3, f"{name}: {len(shown)} labelled ticks on the log RMSE axis")
                check("[" not in fig.axes[0].get_ylabel() or outputs is not None, f"{name}: a unit from a schema-1 file")
                print(f"checked {name}: x = learners, y = {fig.axes[0].get_ylabel()!r}, ticks {shown}")
                continue
            idx = p[f"{split}/rows"][:, 0].astype(int)
            xlabel = ax.get_xlabel()
            if kind == "pred":
                xs = np.asarray(fig.axes[-1].lines[-1].get_xdata(), dtype=float)
                if xlabel.startswith("t [s]"):
                    want = data[f"{split}/t"][:][idx]
                    check(np.all(np.isin(xs, want)) and np.all(np.diff(xs) > 0) and len(xs) >= 10,
                          f"{name}: x label says time but the x data are not the split's time stamps")
                else:
                    col = data[f"{split}/X"].attrs["columns"]
                    col = (col.decode() if isinstance(col, bytes) else col).split(",")[0]
                    check(xlabel.startswith(col), f"{name}: x label '{xlabel}' is neither t [s] nor the first input {col}")
                    want = np.sort(data[f"{split}/X"][:][idx, 0])
                    got = xs[np.isfinite(xs)]
                    check(len(got) >= 0.95 * len(want) and np.all(np.isin(got, want)) and np.all(np.diff(got) >= 0),
                          f"{name}: x label says {col} but the x data are not its values ({len(got)} of {len(want)})")
                if outputs:
                    check(outputs[int(name.split("_")[-1])] in ax.get_ylabel(), f"{name}: y label '{ax.get_ylabel()}' "
                          f"does not name the output {outputs[int(name.split('_')[-1])]}")
            if kind == "residual":
                col = data[f"{split}/X"].attrs["columns"]
                col = (col.decode() if isinstance(col, bytes) else col).split(",")[0]
                xs = ax.collections[0].get_offsets()[:, 0]
                check(xlabel.startswith(col) and np.array_equal(xs, data[f"{split}/X"][:][idx, 0]),
                      f"{name}: x label '{xlabel}' but the x data are not {col}")
            print(f"checked {name}: x = {xlabel!r}, y = {ax.get_ylabel()!r}")
        data.close()
    for fig in FIGURES.values():
        plt.close(fig)


def diagnose_figures():
    """A synthetic diagnose folder: 40 s at 1 kHz on two joints (one slide), with rollouts."""
    folder = tempfile.mkdtemp()
    model = os.path.join(folder, "m.xml")
    with open(model, "w") as f:
        f.write('<mujoco><worldbody><body><joint name="a"/><geom size="1"/><body>'
                '<joint name="b" type="slide"/><geom size="1"/></body></body></worldbody></mujoco>')
    t = np.arange(40000) / 1000.0
    with open(os.path.join(folder, "series.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["split", "t"] + [f"{k}:{j}" for j in "ab" for k in ("tau", "given", "final", "q", "qd")])
        for k, tk in enumerate(t):
            w.writerow(["test", tk] + [v for j in range(2) for v in
                                        (math.sin(tk + j), 0.9 * math.sin(tk + j), math.sin(tk + j) + 1e-3 * (k % 7),
                                         math.cos(tk), -math.sin(tk))])
    report = {"model": model, "rollout": {"split": "test", "horizon_s": 0.1, "windows": 20,
                                          "position_error_before": {"a": 0.0087, "b": 0.0041},
                                          "position_error_after": {"a": 0.0057, "b": 0.0027}}}
    with open(os.path.join(folder, "report.json"), "w") as f:
        json.dump(report, f)
    # Two traced windows of 0.1 s at 1 ms: measured, as given (drifting), extended (closer).
    with open(os.path.join(folder, "rollouts.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["window", "t"] + [f"{k}:{j}" for j in "ab" for k in ("q", "given", "extended")])
        for window, t0 in ((7, 3.0), (2, 1.0)):
            for k in range(101):
                s = k / 1000.0
                w.writerow([window, t0 + s] + [v for j in range(2) for v in (math.sin(s + j), math.sin(s + j) + s * s, math.sin(s + j) + 0.1 * s * s)])
    saved = {}
    real = matplotlib.figure.Figure.savefig
    matplotlib.figure.Figure.savefig = lambda fig, path, **kw: saved.setdefault(os.path.basename(path), fig)
    try:
        diagnose_plots.main(folder)
    finally:
        matplotlib.figure.Figure.savefig = real
    check(set(saved) == {"residuals.png", "states.png", "rollouts.png", "rollouts_trajectories.png"}, f"diagnose figures: {sorted(saved)}")
    for name, fig in saved.items():
        labelled(fig, name)
        print(f"checked {name}: x = {fig.axes[-1].get_xlabel()!r}, y = {[a.get_ylabel() for a in fig.axes]}")
    res = saved["residuals.png"]
    for ax, unit in zip(res.axes, ("N·m", "N")):
        check(unit in ax.get_ylabel(), f"residuals.png: y label '{ax.get_ylabel()}' without {unit}")
        xs = ax.lines[0].get_xdata()
        check(len(xs) <= diagnose_plots.MAX_BINS and xs[0] < 0.1 and xs[-1] > 39.9,
              f"residuals.png: {len(xs)} points from {xs[0]} to {xs[-1]}: not binned over the 40 s")
    check(res.axes[-1].get_xlabel() == "t [s]", "residuals.png: x label is not t [s]")
    ro = saved["rollouts.png"].axes[0]
    check([t.get_text() for t in ro.get_xticklabels()] == ["a", "b"] and ro.get_xlabel() == "joint",
          "rollouts.png: x is not the joints")
    heights = [p.get_height() for p in ro.patches]
    check(heights == [0.0087, 0.0041, 0.0057, 0.0027], f"rollouts.png: bars {heights} are not report.json's errors")
    check("rad or m" in ro.get_ylabel(), f"rollouts.png: y label '{ro.get_ylabel()}' (a hinge and a slide)")
    check("after 0.1 s" in ro.get_ylabel(), f"rollouts.png: y label '{ro.get_ylabel()}' does not give the horizon in s")
    check(ro.get_yscale() == "linear", "rollouts.png: errors within a decade on a log axis")
    trajectories(saved["rollouts_trajectories.png"])
    title = res.axes[0].get_title().replace("\n", " ")
    check("binned by time" in title and "800 bins of 50 samples (0.05 s)" in title,
          f"residuals.png: the title '{title}' does not say how the 40 000 samples were binned")
    rollouts_over_decades()


def trajectories(fig):
    """rollouts_trajectories.png: a column per traced window in file order, per joint its positions
    (measured, as given, extended) and simulated − measured, in the joint's unit, against the time
    into the window."""
    axes = fig.axes
    check(len(axes) == 8, f"rollouts_trajectories.png: {len(axes)} axes, not 2 joints x 2 rows x 2 windows")
    grid = np.array(axes).reshape(4, 2)
    check("window 7" in grid[0, 0].get_title() and "window 2" in grid[0, 1].get_title(),
          f"rollouts_trajectories.png: columns {grid[0, 0].get_title()!r}, {grid[0, 1].get_title()!r} not in file order")
    for row, (j, unit) in enumerate((("a", "rad"), ("a", "rad"), ("b", "m"), ("b", "m"))):
        check(f"[{unit}]" in grid[row, 0].get_ylabel(), f"rollouts_trajectories.png: y label {grid[row, 0].get_ylabel()!r} without {unit}")
    top, bottom = grid[2, 1], grid[3, 1]   # joint b, window 2
    xs = top.lines[0].get_xdata()
    check(abs(xs[0]) < 1e-12 and abs(xs[-1] - 0.1) < 1e-9, f"rollouts_trajectories.png: x from {xs[0]} to {xs[-1]}, not 0..0.1 s")
    check(abs(top.lines[0].get_ydata()[-1] - math.sin(1.1)) < 1e-12, "rollouts_trajectories.png: the measured line is not q:b")
    drift = bottom.lines[0].get_ydata()[-1]
    check(abs(drift - 0.01) < 1e-9, f"rollouts_trajectories.png: as given ends {drift} from the measured, not 0.01")
    check(grid[-1, 0].get_xlabel() == "time into the window [s]", f"rollouts_trajectories.png: x label {grid[-1, 0].get_xlabel()!r}")
    print(f"checked rollouts_trajectories.png: {len(axes)} axes, y = {[a.get_ylabel() for a in axes[:4]]}")


def rollouts_over_decades():
    """Rollout errors three decades apart, hinges only, one rollout diverged: a log y axis in rad,
    every finite error drawn at its height, the divergence marked."""
    saved = {}
    real = matplotlib.figure.Figure.savefig
    matplotlib.figure.Figure.savefig = lambda fig, path, **kw: saved.setdefault(os.path.basename(path), fig)
    units = {j: diagnose_plots.HINGE for j in ("j1", "j2", "j3")}
    report = {"rollout": {"split": "test", "horizon_s": 0.5, "windows": 20,
                          "position_error_before": {"j1": 0.31, "j2": 0.0021, "j3": None},
                          "position_error_after": {"j1": 0.00042, "j2": 0.0019, "j3": 0.05}}}
    try:
        diagnose_plots.rollout_figure(report, units, "")
    finally:
        matplotlib.figure.Figure.savefig = real
    ax = saved["rollouts.png"].axes[0]
    labelled(saved["rollouts.png"], "rollouts.png (decades)")
    check(ax.get_yscale() == "log", "rollouts.png: errors three decades apart on a linear axis")
    check(ax.get_ylabel().startswith("mean |position error| after 0.5 s [rad]"), f"rollouts.png: y label '{ax.get_ylabel()}'")
    lo, hi = ax.get_ylim()
    check(lo <= 0.00042 and hi >= 0.31, f"rollouts.png: y range {lo}..{hi} hides an error")
    check(any(t.get_text() == "diverged" for t in ax.texts), "rollouts.png: the diverged rollout is not marked")
    print(f"checked rollouts.png (decades): y = {ax.get_ylabel()!r}, {ax.get_yscale()} from {lo:.2g} to {hi:.2g}")


def main():
    bench_plots.save = capture
    for bench in sys.argv[2:]:
        bench_figures(bench)
    diagnose_figures()
    for f in FAILURES:
        print("FAIL", f)
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
