#!/usr/bin/python3
"""Figures of `spml bench` results, the way the paper shows them (run by `spml plot`).

  bench_plots.py --out DIR --published DIR [--predictions predictions.h5 ...] [--learners A,B]
                 [--window 2.0] results.csv [results.csv ...]

Writes PNG and PDF into DIR:
Reads results.csv of schema 2 (outputs named, with units) and schema 1 (outputs by index: the
figures then say "output K" and give no units); <output> in file names is the output's index.
  table_<scenario>_<split>_<output>   RMSE and NLLH bars, mean +- std over the repetitions,
                                      ours beside the paper's (one figure per paper table)
  pred_<scenario>_<split>_<output>    prediction +- 2 sigma against the measured signal over
                                      a --window seconds stretch of the test split (a split
                                      without time stamps: against its first input, whole)
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


def read_results(path):
    """results.csv rows with `index` (the output's position), `name` and `unit` added.
    Schema 2 (`output_index` column): `output` is the dataset's column name; schema 1: the index."""
    rows = read_csv(path)
    for r in rows:
        if "output_index" in r:
            r["index"], r["name"], r["unit"] = r["output_index"], r["output"], r.get("unit", "")
        else:
            r["index"], r["name"], r["unit"] = r["output"], "", ""
    return rows


def label(name, unit, index=None):
    """"tau:joint0 [N·m]", "y", or "output 2" where the file does not name it (schema 1)."""
    if not name:
        return f"output {index}"
    return f"{name} [{unit}]" if unit else name


def log_ticks(ax):
    """Labels at 1-2-5 (or finer) steps so a log axis spanning less than a decade still shows
    at least three labelled values, not one power of ten."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
    lo, hi = ax.get_ylim()
    for subs in ((1.0,), (1.0, 2.0, 5.0), (1.0, 1.5, 2.0, 3.0, 5.0, 7.0), tuple(np.arange(1.0, 10.0, 0.5))):
        ticks = [m * 10.0 ** e for e in range(int(math.floor(math.log10(lo))), int(math.ceil(math.log10(hi))) + 1)
                 for m in subs if lo <= m * 10.0 ** e <= hi]
        if len(ticks) >= 3:
            break
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_locator(NullLocator())


def number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def save(fig, out, name, written):
    for ext in ("png", "pdf"):
        path = os.path.join(out, f"{name}.{ext}")
        tmp = path + f".tmp-{os.getpid()}"
        try:
            fig.savefig(tmp, dpi=150, bbox_inches="tight", format=ext)
            os.replace(tmp, path)   # a reader never sees half a figure
        except BaseException:
            if os.path.exists(tmp):   # a full disk must not leave half a figure behind
                os.remove(tmp)
            raise
        written.append(path)
    plt.close(fig)


def table_figures(rows, published, out, written):
    index = {(r["scenario"], r["split"], r["output"]): r["file"] for r in read_csv(os.path.join(published, "tables.csv"))}
    groups = {}
    for r in rows:
        groups.setdefault((r["scenario"], r["split"], r["index"]), []).append(r)
    for key, ours in groups.items():
        if key not in index:
            continue
        # the paper's spelling of one name differs from ours (results.h: canonical_algo)
        paper = {p["algo"].replace("SPGP-from-zeroes", "SPGP-from-zeros"): p
                 for p in read_csv(os.path.join(published, index[key]))}
        algos = [r["algo"] for r in ours]
        algos += [a for a in paper if a not in algos]
        ours_by = {r["algo"]: r for r in ours}
        unit = ours[0]["unit"]
        fig, axes = plt.subplots(1, 2, figsize=(max(8, 0.55 * len(algos) + 4), 4.4))
        for ax, metric, name in ((axes[0], "rmse", "RMSE"), (axes[1], "nllh", "NLLH")):
            x = np.arange(len(algos))
            for shift, source, color, who in ((-0.2, ours_by, OURS, "spml"), (0.2, paper, PAPER, "paper")):
                mean = np.array([number(source[a][metric + "mean"]) if a in source else math.nan for a in algos])
                std = np.array([number(source[a][metric + "std"]) if a in source else math.nan for a in algos])
                ok = np.isfinite(mean)
                std = np.where(np.isfinite(std), std, 0.0)
                ax.bar(x[ok] + shift, mean[ok], 0.4, yerr=std[ok], color=color, label=who, capsize=2)
            ax.set_xticks(x)
            ax.set_xticklabels(algos, rotation=60, ha="right", fontsize=8)
            ax.set_xlabel("learner")
            ax.set_ylabel(f"RMSE [{unit}] (log scale)" if name == "RMSE" and unit else
                          "RMSE (log scale)" if name == "RMSE" else "NLLH (mean negative log density)")
            if name == "RMSE":
                ax.set_yscale("log")
                log_ticks(ax)
            ax.grid(axis="y", alpha=0.3)
        axes[0].legend()
        scenario, split, output = key
        fig.suptitle(f"{scenario} {split}: {label(ours[0]['name'], unit, output)}\n"
                     f"paper: {index[key]}; bars: mean, whiskers: std over repetitions; NLLH where finite",
                     fontsize=10)
        save(fig, out, f"table_{scenario}_{split}_{output}", written)


def column_names(attr):
    """spml/1 stores a dataset's column names as one comma-separated string."""
    if isinstance(attr, bytes):
        attr = attr.decode()
    if isinstance(attr, str):
        return attr.split(",") if attr else []
    return [v.decode() if isinstance(v, bytes) else str(v) for v in attr]


def text_attr(h5, name):
    v = h5.attrs.get(name, "")
    return v.decode() if isinstance(v, bytes) else str(v)


def listed(h5, name, count):
    """A comma-separated root attribute of predictions.h5 (format 2), padded with "" (format 1)."""
    values = text_attr(h5, name).split(",") if text_attr(h5, name) else []
    return values + [""] * (count - len(values))


def abscissa(data, split, idx, window):
    """What the prediction figure is drawn against: the split's time stamps over a --window
    stretch, else (no `t`, as Toy) its first input over the whole split, sorted, else the row
    number. Returns (x values, row order to draw, axis label, input column used or None)."""
    if data is not None and f"{split}/t" in data:
        t = data[f"{split}/t"][:][idx]
        start = t[0] + 0.25 * (t[-1] - t[0])   # a stretch away from the start-up transient
        w = np.flatnonzero((t >= start) & (t <= start + window))
        if len(w) < 2:
            w = np.arange(min(len(t), 200))
        return t, w, "t [s]", None
    if data is not None and data[f"{split}/X"].shape[1] > 0:
        x = data[f"{split}/X"][:][idx, 0]
        return x, np.argsort(x, kind="stable"), None, 0
    return idx.astype(float), np.arange(len(idx)), "row of the split (no time stamps, no dataset)", None


def gaps_broken(x):
    """x with NaN where it jumps by more than 20 median steps (Toy's extrapolation split lies on
    [-4, 0] and [12, 16]): lines are not drawn across a gap that holds no data."""
    x = np.asarray(x, dtype=float).copy()
    steps = np.abs(np.diff(x))
    if len(steps) and np.median(steps) > 0:
        x[1:][steps > 20 * np.median(steps)] = math.nan
    return x


def prediction_figures(path, rows, learners, window, out, written):
    import h5py
    with h5py.File(path, "r") as p:
        scenario = text_attr(p, "scenario")
        data_path = text_attr(p, "data")
        data = h5py.File(data_path, "r") if data_path and os.path.exists(data_path) else None
        if data is None:
            print(f"bench_plots: {path}: dataset '{data_path}' not found: drawing against row numbers, "
                  "no residual-against-position plot", file=sys.stderr)
        splits = [k for k in p.keys() if k.startswith("test")]
        for split in splits:
            y = p[f"{split}/y"][:]
            idx = p[f"{split}/rows"][:, 0].astype(int)
            names = [k for k in p[split].keys() if isinstance(p[f"{split}/{k}"], h5py.Group)]
            outputs, units = listed(p, "outputs", y.shape[1]), listed(p, "units", y.shape[1])
            X = data[f"{split}/X"][:][idx] if data is not None else None
            xcols = column_names(data[f"{split}/X"].attrs.get("columns", "")) if data is not None else []
            xunits = listed(p, "input_units", len(xcols))
            x, order, xlabel, xcol = abscissa(data, split, idx, window)
            if xcol is not None:
                xlabel = label(xcols[xcol], xunits[xcol]) + " (first input; the split has no time stamps)"
            for o in range(y.shape[1]):
                chosen = pick_learners(rows, scenario, split, o, names, learners)
                if not chosen:
                    continue
                ylabel = label(outputs[o], units[o], o)
                fig, axes = plt.subplots(len(chosen), 1, figsize=(10, 2.2 * len(chosen) + 0.8), sharex=True, squeeze=False,
                                         constrained_layout=True)
                xs = gaps_broken(x[order])
                for ax, name in zip(axes[:, 0], chosen):
                    mean = p[f"{split}/{name}/rep0/mean"][:, o]
                    if xcol is None:
                        ax.plot(xs, y[order, o], color="black", lw=1.0, label="measured")
                    else:   # samples, not a signal: no line between them
                        ax.scatter(x[order], y[order, o], s=3, color="black", label="measured")
                    ax.plot(xs, mean[order], color=OURS, lw=1.0, label=f"{name} (rep 1)")
                    if f"{split}/{name}/rep0/std" in p:
                        sd = p[f"{split}/{name}/rep0/std"][:, o]
                        ax.fill_between(xs, mean[order] - 2 * sd[order], mean[order] + 2 * sd[order], color=OURS,
                                        alpha=0.25, label="±2σ")
                    rmse = math.sqrt(float(np.mean((mean - y[:, o]) ** 2)))
                    ax.set_title(f"{name}: RMSE {rmse:.3g}{' ' + units[o] if units[o] else ''} over the whole split",
                                 fontsize=9)
                    ax.set_ylabel(ylabel, fontsize=8)
                    ax.legend(fontsize=7, loc="best")
                    ax.grid(alpha=0.3)
                axes[-1, 0].set_xlabel(xlabel)
                fig.suptitle(f"{scenario} {split}: {ylabel}, prediction against the measured signal", fontsize=10)
                save(fig, out, f"pred_{scenario}_{split}_{o}", written)

                if X is None or X.shape[1] == 0:
                    continue
                fig, ax = plt.subplots(figsize=(8, 4.2))
                for k, name in enumerate(chosen):
                    res = y[:, o] - p[f"{split}/{name}/rep0/mean"][:, o]
                    ax.scatter(X[:, 0], res, s=2, alpha=0.4, color=f"C{k}", label=name)
                ax.axhline(0, color="black", lw=0.6)
                ax.set_xlabel(label(xcols[0], xunits[0]) if xcols else "input 0")
                ax.set_ylabel(f"measured − predicted{' [' + units[o] + ']' if units[o] else ''}")
                ax.legend(markerscale=5, fontsize=8)
                ax.grid(alpha=0.3)
                ax.set_title(f"{scenario} {split}: residual of {outputs[o] or f'output {o}'}\n"
                             f"against {xcols[0] if xcols else 'input 0'}", fontsize=10)
                save(fig, out, f"residual_{scenario}_{split}_{o}", written)
        if data is not None:
            data.close()


def pick_learners(rows, scenario, split, output, available, wanted):
    """The learners asked for, else LLS (the model alone) and the two best by RMSE."""
    if wanted:
        return [a for a in wanted if a in available]
    ranked = sorted((number(r["rmsemean"]), r["algo"]) for r in rows
                    if r["scenario"] == scenario and r["split"] == split and r["index"] == str(output)
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
        rows += read_results(f)
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
