"""Learner: any spml learner plugin (or composition "A-B", "it-A-B") as a scikit-learn-style
estimator. The parameters are the learner's config keys (spml.learner_info(name)["keys"])
plus `name` and `seed`; a key left at None takes the learner's own default, exactly as a
`spml bench` run without --set. sklearn.base.clone, GridSearchCV-style set_params and
get_params work; the class does not depend on scikit-learn.
"""

import numpy as np

from . import _spml


def _config_text(value):
    """A config value as the text spml's key tables check: numbers written so they read
    back exactly, booleans as 1/0, sequences comma-separated (a 'numbers' key)."""
    if isinstance(value, (bool, np.bool_)):
        return "1" if value else "0"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple, np.ndarray)):
        return ",".join(_config_text(v) for v in value)
    raise ValueError(f"config value {value!r}: expected a number, a string or a list of numbers")


class Learner:
    """spml.Learner(name, seed=1, **config).

    fit(X, Y, model=None, phi=None, param_names=None, prior=None, truth=None)
        X: rows x inputs; Y: rows x outputs (or 1-D for one output). A learner that uses the
        parametric model (LLS, SPGP, ..., compositions starting with one) needs it, either
        model=spml.parametric_model(data[, mjcf]) (Phi is then computed for every X given
        to fit and predict, as `spml bench` does) or phi=Phi (outputs*rows x params,
        output-major: row o*rows+i is phi_o(x_i)) with optional parameter names, prior and
        true coefficients; predict then needs phi= for its X as well.
    predict(X, return_std=False, phi=None)
        The mean (rows x outputs); with return_std also the predictive standard deviation
        (noise included), None for a learner without a variance.
    score(X, Y, phi=None)
        R^2, as scikit-learn's regressors (for cross_val_score, GridSearchCV).
    After fit: coef_ (fitted parametric coefficients or None), notes_ (the fit's warnings),
    n_features_in_, flags (what the learner is: uses_model, variance, deterministic, ...).
    """

    _estimator_type = "regressor"

    def __init__(self, name, seed=1, **config):
        self.name = name
        self.seed = seed
        self._keys = sorted(_spml.learner_info(name)["keys"])
        self._config = {}
        self.set_params(**config)

    def get_params(self, deep=True):
        params = {"name": self.name, "seed": self.seed}
        params.update({k: self._config.get(k) for k in self._keys})
        return params

    def set_params(self, **params):
        if "name" in params and params["name"] != self.name:
            raise ValueError(f"set_params: name cannot change ({self.name!r} -> {params['name']!r}); make a new Learner")
        params.pop("name", None)
        if "seed" in params:
            self.seed = params.pop("seed")
        for key, value in params.items():
            if key not in self._keys:
                raise ValueError(_spml.config_problem(self.name, key, ""))
            if value is not None:
                problem = _spml.config_problem(self.name, key, _config_text(value))
                if problem:
                    raise ValueError(problem)
            self._config[key] = value
        return self

    def fit(self, X, Y, model=None, phi=None, param_names=None, prior=None, truth=None):
        if isinstance(self.seed, (bool, np.bool_)) or not isinstance(self.seed, (int, np.integer)) or not 0 <= self.seed < 2**64:
            raise ValueError(f"seed {self.seed!r}: expected a whole number 0 ... 2**64-1")
        if model is not None and phi is not None:
            raise ValueError("fit: pass model= or phi=, not both")
        X = np.asarray(X, dtype=np.float64)
        Y = np.asarray(Y, dtype=np.float64)
        self._one_output = Y.ndim == 1
        if self._one_output:
            Y = Y.reshape(-1, 1)
        if model is not None:
            phi, param_names, prior, truth = model.phi(X), model.param_names, model.prior, model.truth
        config = [(k, _config_text(v)) for k, v in sorted(self._config.items()) if v is not None]
        native = _spml.NativeLearner(self.name)
        native.fit(X, Y, phi, list(param_names or []), prior, truth, config, int(self.seed))
        self._native, self._model = native, model
        self.n_features_in_ = X.shape[1]
        self.coef_ = native.coefficients()
        self.notes_ = native.notes()
        return self

    def predict(self, X, return_std=False, phi=None):
        native = getattr(self, "_native", None)
        if native is None:
            raise ValueError(f"learner {self.name!r}: predict before fit")
        X = np.asarray(X, dtype=np.float64)
        if self._model is not None:
            phi = self._model.phi(X)
        mean, var = native.predict(X, phi)
        std = None if var is None else np.sqrt(var)
        if self._one_output:
            mean = mean[:, 0]
            std = None if std is None else std[:, 0]
        return (mean, std) if return_std else mean

    def score(self, X, Y, phi=None):
        """R^2 of the predicted mean, averaged over the outputs (scikit-learn's convention for
        regressors, so cross_val_score and GridSearchCV work; spml.score gives bench's
        RMSE and NLLH)."""
        Y = np.asarray(Y, dtype=np.float64).reshape(len(X), -1)
        mean = np.asarray(self.predict(X, phi=phi)).reshape(Y.shape)
        residual = ((Y - mean) ** 2).sum(axis=0)
        total = ((Y - Y.mean(axis=0)) ** 2).sum(axis=0)
        return float(np.mean(1 - residual / total))

    def __getstate__(self):
        # An unfitted learner is its parameters (so joblib can ship it to workers); a fitted
        # one's state lives inside the plugin library, which has no serialisation.
        if getattr(self, "_native", None) is not None:
            raise TypeError(f"a fitted spml.Learner ({self.name}) cannot be pickled: its state lives in the learner plugin")
        return self.__dict__

    @property
    def flags(self):
        return _spml.learner_info(self.name)["flags"]

    def __repr__(self):
        set_ = ", ".join(f"{k}={v!r}" for k, v in sorted(self._config.items()) if v is not None)
        return f"Learner({self.name!r}, seed={self.seed!r}{', ' + set_ if set_ else ''})"
