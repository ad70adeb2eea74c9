#!/usr/bin/python3
"""Reads a file written by `spml generate` with plain h5py (no spml code) and checks the
spml/1 contract: format attribute, per-split X/Y with `columns` matching the widths."""
import sys

import h5py
import numpy as np

path = sys.argv[1]
with h5py.File(path, "r") as f:
    fmt = f.attrs["format"]
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    assert fmt == "spml/1", fmt
    splits = [k for k in f.keys() if k != "model"]
    assert splits, "no splits"
    for name in splits:
        g = f[name]
        X, Y = g["X"][()], g["Y"][()]
        assert X.dtype == np.float64 and Y.dtype == np.float64
        assert X.shape[0] == Y.shape[0] > 0
        xc = g["X"].attrs["columns"].split(",")
        yc = g["Y"].attrs["columns"].split(",")
        assert len(xc) == X.shape[1] and len(yc) == Y.shape[1], (xc, yc)
        assert np.isfinite(X).all() and np.isfinite(Y).all()
        print(name, X.shape, Y.shape, xc[0], yc[0])
    m = f["model"]
    names = m.attrs["param_names"].split(",")
    assert len(names) == m["truth"].shape[0] == m["prior"].shape[0]
    print("model", m.attrs["name"], len(names), "parameters")
print("h5py read OK")
