#!/usr/bin/python3
"""Writes the bad or unusual inputs of issue #9 into DIR, each derived from a valid Toy or
arm dataset (TOY, ARM given on the command line) with h5py alone, so the reader under test
never produced them. Used by tests/test_bad_input.cc."""
import shutil
import sys

import h5py
import numpy as np

toy, arm, out = sys.argv[1], sys.argv[2], sys.argv[3]


def copy(src, name):
    path = f"{out}/{name}.h5"
    shutil.copy(src, path)
    return path


def set_matrix(f, group, name, data, columns):
    del f[group][name]
    f[group].create_dataset(name, data=data).attrs["columns"] = columns


# Y wider than the model's outputs: toy with an extra target column z.
with h5py.File(copy(toy, "wide_y"), "r+") as f:
    for g in ("train", "test_interp", "test_extrap"):
        y = f[g]["Y"][:]
        set_matrix(f, g, "Y", np.column_stack([y, y * 0.5]), "y,z")

# Test X with a junk column and x moved: the names must decide, not the positions.
with h5py.File(copy(toy, "junk_test_x"), "r+") as f:
    x = f["test_interp"]["X"][:]
    set_matrix(f, "test_interp", "X", np.column_stack([np.full_like(x[:, 0], 1e3), x[:, 0]]), "junk,x")

# The same data with the test columns merely reordered (and renamed consistently): valid.
with h5py.File(copy(arm, "arm_reordered"), "r+") as f:
    for g in f:
        if g == "model":
            continue
        cols = f[g]["X"].attrs["columns"].split(",")
        x = f[g]["X"][:]
        order = list(range(3, 6)) + list(range(0, 3)) + list(range(6, 9)) if g != "train" else list(range(9))
        set_matrix(f, g, "X", x[:, order], ",".join(cols[i] for i in order))

# Duplicate and empty column names; NaN in t; a value that overflows the dynamics.
with h5py.File(copy(arm, "duplicate_column"), "r+") as f:
    x = f["train"]["X"][:]
    cols = f["train"]["X"].attrs["columns"].split(",")
    set_matrix(f, "train", "X", np.column_stack([x, x[:, 0]]), ",".join(cols + [cols[0]]))
with h5py.File(copy(arm, "empty_column"), "r+") as f:
    cols = f["train"]["X"].attrs["columns"].split(",")
    cols[1] = ""
    f["train"]["X"].attrs["columns"] = ",".join(cols)
with h5py.File(copy(toy, "nan_t"), "r+") as f:
    t = f["train"]["t"][:] if "t" in f["train"] else np.arange(f["train"]["X"].shape[0]) * 0.01
    t[3] = np.nan
    if "t" in f["train"]:
        del f["train"]["t"]
    f["train"].create_dataset("t", data=t)
with h5py.File(copy(arm, "huge_qd"), "r+") as f:
    x = f["train"]["X"][:]
    cols = f["train"]["X"].attrs["columns"].split(",")
    x[10, cols.index("qd:joint0")] = 1e308
    set_matrix(f, "train", "X", x, ",".join(cols))

# Five rows for 18 parameters; constant data (nothing moves).
for name, rows in (("five_rows", 5), ("constant", 2000)):
    with h5py.File(copy(arm, name), "r+") as f:
        x, y = f["train"]["X"][:rows], f["train"]["Y"][:rows]
        if name == "constant":
            x[:] = x[0]
            y[:] = y[0]
        xc, yc = f["train"]["X"].attrs["columns"], f["train"]["Y"].attrs["columns"]
        set_matrix(f, "train", "X", x, xc)
        set_matrix(f, "train", "Y", y, yc)
        if "t" in f["train"]:
            del f["train"]["t"]

# A dataset with no model group at all.
with h5py.File(copy(toy, "no_model"), "r+") as f:
    del f["model"]

# The arm without its model group: a measured-looking dataset that needs --model.
with h5py.File(copy(arm, "arm_no_model"), "r+") as f:
    del f["model"]
