"""spml from Python: spml/1 datasets as NumPy arrays, every learner plugin as a
scikit-learn-style estimator, the parametric model of a dataset or of any MJCF, identify and
diagnose. Everything runs in spml's C++ libraries (the module `_spml`); this file only
adapts the calling conventions. README section "Python" shows a Toy row reproduced.

    import spml
    ds = spml.read_dataset("toy.h5")               # {"splits": {...}, "model": ..., "provenance": ...}
    model = spml.parametric_model("toy.h5")        # Phi(x) as `spml bench` gives it to the learners
    gp = spml.Learner("LLS-GP", seed=1, max_evals=500).fit(X, Y, model=model)
    mean, std = gp.predict(Xq, return_std=True)

Errors are spml's own messages: FileNotFoundError for a missing input file, ValueError for
a bad value or dataset, RuntimeError for a plugin that cannot load or a fit that failed.
"""

import os

import numpy as np

from . import _spml
from ._spml import ParametricModel
from .learner import Learner

__version__ = _spml.version
__all__ = [
    "read_dataset", "write_dataset", "learners", "learner_info", "Learner", "parametric_model",
    "ParametricModel", "regressor", "identify", "diagnose", "score", "add_learner_path",
    "add_plugin_path",
]


def read_dataset(path, allow_nonfinite=False):
    """Reads and validates an spml/1 file.

    Returns {"splits": {name: {"X", "Y", "t" (or None), "x_columns", "y_columns"}} in the
    file's order, "model": {"name", "param_names", "prior", "truth", "mjcf_path",
    "mjcf_xml"} or None, "provenance": {attribute: text}}, so that
    write_dataset(out, **read_dataset(path)) copies a dataset.
    """
    return _spml.read_dataset(os.fspath(path), allow_nonfinite)


def write_dataset(path, splits, model=None, provenance=None):
    """Writes an spml/1 file atomically (complete under `path` or not at all), after the
    checks every reader applies. `splits` maps split names to dicts as read_dataset returns
    them ("t" optional); dicts keep their order, and so does the file."""
    _spml.write_dataset(os.fspath(path), splits, model, provenance)


def learners(compositions=False):
    """The learner plugins found (the shipped ones, $SPML_LEARNER_PATH, add_learner_path);
    with compositions=True also A-B and it-A-B for every parametric A and non-parametric B,
    as `spml bench --learners all` runs them."""
    return _spml.learners(compositions)


def learner_info(name):
    """A learner's summary, flags and config keys ({key: {"type", "min", "max", "default",
    "help"}}; default None: worked out from the data)."""
    return _spml.learner_info(name)


def add_learner_path(path):
    """Adds a learner library or a folder of them (like --learner-path)."""
    _spml.add_learner_path(os.fspath(path))


def add_plugin_path(path):
    """Adds a force-plugin library or a folder of them (like --plugin-path); call it before
    loading a model that declares the plugin."""
    _spml.add_plugin_path(os.fspath(path))


def parametric_model(data, mjcf=None, split="train"):
    """The parametric model Phi(x) of a dataset, chosen as `spml bench` chooses it: the MJCF
    (or URDF) `mjcf` if given, else the analytic model the dataset's model/name registers
    (toy, via, planar_arm3), else the dataset's own MJCF. `data` is a path or a
    read_dataset() dict; the model reads X laid out like that split's columns.
    Returns a ParametricModel: .phi(X) (outputs*rows x params, output-major), .predict(X,
    theta), .param_names, .prior, .truth, .x_columns, .y_columns."""
    if not isinstance(data, dict):
        data = os.fspath(data)
    return ParametricModel(data, "" if mjcf is None else os.fspath(mjcf), split)


def regressor(model, offsets=False, plugin_path=()):
    """The identification regressor of an MJCF/URDF: its standard parameters
    (standard_names, standard_values), base parameters (rank, names, prior: the model's own
    values), the QR's independent/dependent columns and Kd (beta = pi_ind + Kd pi_dep).
    Keys shared with `spml regressor --json` mean the same."""
    return _spml.regressor(os.fspath(model), offsets, [os.fspath(p) for p in plugin_path])


def identify(model, data, split="train", offsets=False, plugin_path=()):
    """Least-squares identification of the model's base parameters on one split of `data`
    (a path or a read_dataset() dict); every other split is scored held out. The keys of
    `spml identify --json`: names, estimate, std_error, prior, sigma, condition_number,
    errors [{split, rows, relative_error, rmse}]."""
    if not isinstance(data, dict):
        data = os.fspath(data)
    return _spml.identify(os.fspath(model), data, split, offsets, [os.fspath(p) for p in plugin_path])


def diagnose(model, data, out=None, cross=(), plugin_path=(), **options):
    """`spml diagnose`: returns the report.json contents as a dict. With `out`, writes
    report.json, report.md, extended.xml and series.csv there as the command does (the plots
    are drawn by `spml diagnose`, not here). Options as the command's, with underscores:
    fit_split, test_split, holdout, bic_threshold, min_gain, max_causes, still_speed,
    rollout_seconds, rollouts, estimator ("iv" or "ls")."""
    return _spml.diagnose(os.fspath(model), os.fspath(data), "" if out is None else os.fspath(out),
                          cross=[os.fspath(c) for c in cross], plugin_path=[os.fspath(p) for p in plugin_path],
                          **options)


def score(Y, mean, var=None):
    """RMSE and NLLH per output exactly as `spml bench` scores a split:
    {"rmse": [...], "nllh": [...]} (NLLH inf without a variance)."""
    return _spml.score(_as_2d(Y), _as_2d(mean), None if var is None else _as_2d(var))


def _as_2d(a):
    a = np.asarray(a, dtype=np.float64)
    return a.reshape(-1, 1) if a.ndim == 1 else a


