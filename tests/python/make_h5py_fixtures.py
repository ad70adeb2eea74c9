#!/usr/bin/python3
"""Writes spml/1 files with h5py alone (an independent writer) into DIR: one valid file and
one file per kind of bad input the reader must reject. Used by tests/test_cli.cc."""
import os
import sys

import h5py
import numpy as np

out = sys.argv[1]
os.makedirs(out, exist_ok=True)
rng = np.random.default_rng(7)


def good(path, **kw):
    with h5py.File(path, "w") as f:
        f.attrs["format"] = kw.get("format", "spml/1")
        if kw.get("drop_format"):
            del f.attrs["format"]
        f.attrs["scenario"] = "h5py-fixture"
        g = f.create_group("train")
        X = kw.get("X", np.column_stack([np.arange(10.0), np.arange(10.0) ** 2]))
        Y = kw.get("Y", np.arange(10.0).reshape(-1, 1) * 3.0)
        if not kw.get("drop_x"):
            g.create_dataset("X", data=X).attrs["columns"] = kw.get("xcols", "q:j0,qd:j0")
        if not kw.get("drop_y"):
            g.create_dataset("Y", data=Y).attrs["columns"] = "tau:j0"
        g.create_dataset("t", data=np.arange(X.shape[0]) * 0.01)
        m = f.create_group("model")
        m.attrs["name"] = "custom"
        m.attrs["param_names"] = "a,b"
        m.create_dataset("prior", data=[1.0, 2.0])


good(f"{out}/good.h5")
good(f"{out}/no_format.h5", drop_format=True)
good(f"{out}/bad_version.h5", format="spml/2")
good(f"{out}/missing_x.h5", drop_x=True)
good(f"{out}/missing_y.h5", drop_y=True)
good(f"{out}/rows_differ.h5", Y=np.zeros((9, 1)))
good(f"{out}/columns_mismatch.h5", xcols="q:j0,qd:j0,qdd:j0")
bad = np.column_stack([np.arange(10.0), np.arange(10.0)])
bad[3, 1] = np.nan
bad[7, 0] = np.inf
good(f"{out}/nonfinite.h5", X=bad)
good(f"{out}/empty_split.h5", X=np.zeros((0, 2)), Y=np.zeros((0, 1)))
with open(f"{out}/not_hdf5.h5", "w") as f:
    f.write("time,q\n0,1\n")
data = open(f"{out}/good.h5", "rb").read()
with open(f"{out}/truncated.h5", "wb") as f:
    f.write(data[: len(data) // 3])
