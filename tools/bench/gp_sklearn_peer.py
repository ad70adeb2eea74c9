#!/usr/bin/python3
"""One GP log-marginal-likelihood + gradient evaluation, spml vs scikit-learn, same data.

Both evaluate an ARD RBF kernel plus Gaussian noise with every hyper-parameter at 1.0 on
the first --rows rows of a dataset's train split (one output column) and print the time,
the ratio and both log-likelihoods (which must agree). With --fit, both also fit the GP to
convergence from there (targets divided by their RMS, L-BFGS with analytic gradients, one
start, bounds as spml's) and print time, evaluations and the LML reached.

    /usr/bin/python3 tools/bench/gp_sklearn_peer.py --data out/simdyn-ll.h5 [--rows 2000] [--fit]
"""
import argparse
import json
import statistics
import subprocess
import sys
import time

import h5py
import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--rows", type=int, default=2000)
    ap.add_argument("--output", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--bench-gp", default="build/bin/bench_gp")
    ap.add_argument("--fit", action="store_true", help="also time a full hyper-parameter fit")
    args = ap.parse_args()

    with h5py.File(args.data, "r") as f:
        X = f["train/X"][: args.rows]
        y = f["train/Y"][: args.rows, args.output]
    kernel = ConstantKernel(1.0) * RBF(length_scale=np.ones(X.shape[1])) + WhiteKernel(1.0)
    gp = GaussianProcessRegressor(kernel=kernel, optimizer=None, normalize_y=False).fit(X, y)
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        lml_sk, _ = gp.log_marginal_likelihood(gp.kernel_.theta, eval_gradient=True)
        times.append(time.perf_counter() - t0)
    t_sk = statistics.median(times)

    ours = json.loads(subprocess.run(
        [args.bench_gp, "--data", args.data, "--rows", str(args.rows), "--output", str(args.output)]
        + (["--fit"] if args.fit else []),
        check=True, capture_output=True, text=True).stdout)
    print(f"rows {X.shape[0]}, inputs {X.shape[1]}: one LML + gradient")
    print(f"  spml          {ours['lml_grad_seconds']:9.4f} s   LML {ours['lml']:.6f}")
    print(f"  scikit-learn  {t_sk:9.4f} s   LML {lml_sk:.6f}")
    print(f"  ratio (scikit-learn / spml) {t_sk / ours['lml_grad_seconds']:.1f}x")
    rel = abs(ours["lml"] - lml_sk) / max(1.0, abs(lml_sk))
    if rel > 1e-8:
        print(f"  LML MISMATCH: relative difference {rel:.2e}")
        return 1
    if args.fit:
        ys = y / np.sqrt(np.mean(y ** 2))
        evals = [0]
        kernel = (ConstantKernel(1.0, (1e-8, 1e12)) * RBF(np.ones(X.shape[1]), (1e-3, 1e5))
                  + WhiteKernel(1.0, (1e-6, 1e12)))

        def optimizer(obj_func, initial_theta, bounds):
            from scipy.optimize import minimize

            def counted(theta):
                evals[0] += 1
                return obj_func(theta, eval_gradient=True)
            r = minimize(counted, initial_theta, method="L-BFGS-B", jac=True, bounds=bounds,
                         options={"maxfun": 1000})
            return r.x, r.fun
        t0 = time.perf_counter()
        fitted = GaussianProcessRegressor(kernel=kernel, optimizer=optimizer, normalize_y=False).fit(X, ys)
        t_fit = time.perf_counter() - t0
        print(f"rows {X.shape[0]}: full fit from every hyper-parameter at 1.0 (targets / RMS)")
        print(f"  spml          {ours['fit_seconds']:9.2f} s   {ours['fit_evaluations']:4d} evaluations   "
              f"LML {ours['fit_lml']:.3f}")
        print(f"  scikit-learn  {t_fit:9.2f} s   {evals[0]:4d} evaluations   LML {fitted.log_marginal_likelihood_value_:.3f}")
        print(f"  ratio (scikit-learn / spml) {t_fit / ours['fit_seconds']:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
