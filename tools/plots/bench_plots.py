#!/usr/bin/python3
"""Figures of `spml bench` results, the way the paper shows them (run by `spml plot`).

  bench_plots.py --out DIR --published DIR [--predictions predictions.h5 ...] [--learners A,B]
                 [--window 2.0] results.csv [results.csv ...]

Writes PNG and PDF into DIR:
  table_<scenario>_<split>_<output>   RMSE and NLLH bars, mean +- std over the repetitions,
                                      ours beside the paper's (one figure per paper table)
  pred_<scenario>_<split>_<output>    prediction +- 2 sigma against the measured signal over
                                      a --window seconds stretch of the test split
  residual_<scenario>_<split>_<output>  residual (measured - predicted) against the first
                                      position input (SimDyn: where the friction band sits)
Prints one line per file written.
"""
import argparse
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

OURS, PAPER = "tab:blue", "tab:gray"


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def save(fig, out, name, written):
    for ext in ("png", "pdf"):
        path = os.path.join(out, f"{name}.{ext}")
        tmp = path + f".tmp-{os.getpid()}"
        fig.savefig(tmp, dpi=150, bbox_inches="tight", format=ext)
        os.replace(tmp, path)   # a reader never sees half a figure
        written.append(path)
    plt.close(fig)


def table_figures(rows, published, out, written):
    index = {(r["scenario"], r["split"], r["output"]): r["file"] for r in read_csv(os.path.join(published, "tables.csv"))}
    groups = {}
    for r in rows:
        groups.setdefault((r["scenario"], r["split"], r["output"]), []).append(r)
    for key, ours in groups.items():
        if key not in index:
            continue
        paper = {p["algo"]: p for p in read_csv(os.path.join(published, index[key]))}
        algos = [r["algo"] for r in ours]
        algos += [a for a in paper if a not in algos]
        ours_by = {r["algo"]: r for r in ours}
        fig, axes = plt.subplots(1, 2, figsize=(max(8, 0.55 * len(algos) + 4), 4.2))
        for ax, metric, label in ((axes[0], "rmse", "RMSE"), (axes[1], "nllh", "NLLH")):
            x = np.arange(len(algos))
            for shift, source, color, name in ((-0.2, ours_by, OURS, "spml"), (0.2, paper, PAPER, "paper")):
                mean = np.array([number(source[a][metric + "mean"]) if a in source else math.nan for a in algos])
                std = np.array([number(source[a][metric + "std"]) if a in source else math.nan for a in algos])
                ok = np.isfinite(mean)
                std = np.where(np.isfinite(std), std, 0.0)
                ax.bar(x[ok] + shift, mean[ok], 0.4, yerr=std[ok], color=color, label=name, capsize=2)
            ax.set_xticks(x)
            ax.set_xticklabels(algos, rotation=60, ha="right", fontsize=8)
            ax.set_ylabel(label)
            ax.set_yscale("log" if label == "RMSE" else "linear")
            ax.grid(axis="y", alpha=0.3)
        axes[0].legend()
        scenario, split, output = key
        fig.suptitle(f"{scenario} {split} output {output} (paper: {index[key]}); "
                     f"bars: mean, whiskers: std over repetitions; NLLH only where finite")
        save(fig, out, f"table_{scenario}_{split}_{output}", written)


def column_names(attr):
    """spml/1 stores a dataset's column names as one comma-separated string."""
    if isinstance(attr, bytes):
        attr = attr.decode()
    if isinstance(attr, str):
        return attr.split(",") if attr else []
    return [v.decode() if isinstance(v, bytes) else str(v) for v in attr]


def prediction_figures(path, rows, learners, window, out, written):
    import h5py
    with h5py.File(path, "r") as p:
        scenario = p.attrs.get("scenario", "")
        scenario = scenario.decode() if isinstance(scenario, bytes) else str(scenario)
        data_path = p.attrs.get("data", "")
        data_path = data_path.decode() if isinstance(data_path, bytes) else str(data_path)
        data = h5py.File(data_path, "r") if data_path and os.path.exists(data_path) else None
        if data is None:
            print(f"bench_plots: {path}: dataset '{data_path}' not found: drawing against sample numbers, "
                  "no residual-against-position plot", file=sys.stderr)
        splits = [k for k in p.keys() if k.startswith("test")]
        for split in splits:
            y = p[f"{split}/y"][:]
            idx = p[f"{split}/rows"][:, 0].astype(int)
            names = [k for k in p[split].keys() if isinstance(p[f"{split}/{k}"], h5py.Group)]
            t = data[f"{split}/t"][:][idx] if data is not None and f"{split}/t" in data else idx.astype(float)
            X = data[f"{split}/X"][:][idx] if data is not None else None
            xcols = column_names(data[f"{split}/X"].attrs.get("columns", "")) if data is not None else []
            for o in range(y.shape[1]):
                chosen = pick_learners(rows, scenario, split, o, names, learners)
                if not chosen:
                    continue
                start = t[0] + 0.25 * (t[-1] - t[0])   # a stretch away from the start-up transient
                w = (t >= start) & (t <= start + window)
                if w.sum() < 2:
                    w = slice(0, min(len(t), 200))
                fig, axes = plt.subplots(len(chosen), 1, figsize=(10, 2.2 * len(chosen) + 0.8), sharex=True, squeeze=False)
                for ax, name in zip(axes[:, 0], chosen):
                    mean = p[f"{split}/{name}/rep0/mean"][:, o]
                    ax.plot(t[w], y[w, o], color="black", lw=1.0, label="measured")
                    ax.plot(t[w], mean[w], color=OURS, lw=1.0, label=f"{name} (rep 1)")
                    if f"{split}/{name}/rep0/std" in p:
                        sd = p[f"{split}/{name}/rep0/std"][:, o]
                        ax.fill_between(t[w], mean[w] - 2 * sd[w], mean[w] + 2 * sd[w], color=OURS, alpha=0.25,
                                        label="+-2 sigma")
                    rmse = math.sqrt(float(np.mean((mean - y[:, o]) ** 2)))
                    ax.set_title(f"{name}: RMSE {rmse:.3g} over the whole split", fontsize=9)
                    ax.legend(fontsize=7, loc="upper right")
                    ax.grid(alpha=0.3)
                axes[-1, 0].set_xlabel("t [s]" if data is not None else "sample")
                fig.suptitle(f"{scenario} {split} output {o}: prediction against the measured signal")
                save(fig, out, f"pred_{scenario}_{split}_{o}", written)

                if X is None or X.shape[1] == 0:
                    continue
                fig, ax = plt.subplots(figsize=(8, 4.2))
                for k, name in enumerate(chosen):
                    res = y[:, o] - p[f"{split}/{name}/rep0/mean"][:, o]
                    ax.scatter(X[:, 0], res, s=2, alpha=0.4, color=f"C{k}", label=name)
                ax.axhline(0, color="black", lw=0.6)
                ax.set_xlabel(xcols[0] if xcols else "input 0")
                ax.set_ylabel("measured - predicted")
                ax.legend(markerscale=5, fontsize=8)
                ax.grid(alpha=0.3)
                ax.set_title(f"{scenario} {split} output {o}: residual against {xcols[0] if xcols else 'input 0'}")
                save(fig, out, f"residual_{scenario}_{split}_{o}", written)
        if data is not None:
            data.close()


def pick_learners(rows, scenario, split, output, available, wanted):
    """The learners asked for, else LLS (the model alone) and the two best by RMSE."""
    if wanted:
        return [a for a in wanted if a in available]
    ranked = sorted((number(r["rmsemean"]), r["algo"]) for r in rows
                    if r["scenario"] == scenario and r["split"] == split and r["output"] == str(output)
                    and r["algo"] in available and r["algo"] not in ("LLS-prior", "LLS-simulated"))
    chosen = ["LLS"] if "LLS" in available else []
    chosen += [a for _, a in ranked if a not in chosen][:2]
    return chosen


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("results", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--published", required=True)
    ap.add_argument("--predictions", action="append", default=[])
    ap.add_argument("--learners", default="")
    ap.add_argument("--window", type=float, default=2.0)
    args = ap.parse_args()
    rows = []
    for f in args.results:
        rows += read_csv(f)
    os.makedirs(args.out, exist_ok=True)
    written = []
    table_figures(rows, args.published, args.out, written)
    wanted = [a for a in args.learners.split(",") if a]
    for p in args.predictions:
        prediction_figures(p, rows, wanted, args.window, args.out, written)
    for w in written:
        print(w)
    if not written:
        print("bench_plots: nothing to draw (no paper table matches these results, and no predictions given)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
