#!/usr/bin/python3
"""The Python module `spml` against spml's own command line: datasets written from Python
read back to the bit (with spml and with plain h5py), Toy rows fitted from Python equal to
`spml bench`'s to the bit, identify and diagnose equal to the commands' JSON, the sklearn
estimator contract, errors that name the file. Run by ctest (PythonModule) with
PYTHONPATH=<build>/python; environment: SPML_BIN (the spml binary), SPML_SOURCE_DIR,
SPML_BUILD_DIR and SPML_CMAKE (for the install check)."""
import json
import os
import subprocess
import sys
import tempfile
import unittest

import h5py
import numpy as np

import spml

SPML = os.environ["SPML_BIN"]
SOURCE = os.environ["SPML_SOURCE_DIR"]
ARM = os.path.join(SOURCE, "mjcf", "planar_arm3.xml")


def run(*args):
    return subprocess.run([SPML, *args], check=True, capture_output=True, text=True).stdout


class Fixture(unittest.TestCase):
    """One Toy dataset and one `spml bench --learners LLS,GP --reps 1` run for all tests."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.dir = cls.tmp.name
        cls.toy = os.path.join(cls.dir, "toy.h5")
        run("generate", "--scenario", "toy", "--out", cls.toy, "--quiet")

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()


class Datasets(Fixture):
    def test_round_trip_is_exact_with_spml_and_h5py(self):
        ds = spml.read_dataset(self.toy)
        self.assertEqual(list(ds["splits"]), ["train", "test_interp", "test_extrap"])
        self.assertEqual(ds["model"]["name"], "toy")
        self.assertEqual(ds["provenance"]["scenario"], "toy")
        copy = os.path.join(self.dir, "copy.h5")
        spml.write_dataset(copy, **ds)
        again = spml.read_dataset(copy)
        self.assertEqual(again["provenance"], ds["provenance"])
        self.assertEqual(list(again["splits"]), list(ds["splits"]))
        for key in ("name", "param_names", "mjcf_path", "mjcf_xml"):
            self.assertEqual(again["model"][key], ds["model"][key])
        for key in ("prior", "truth"):
            self.assertEqual(again["model"][key].tobytes(), ds["model"][key].tobytes())
        with h5py.File(copy, "r") as f, h5py.File(self.toy, "r") as g:
            self.assertEqual(f.attrs["format"], "spml/1")
            for name, s in ds["splits"].items():
                for part in ("X", "Y"):
                    # to the bit: spml's arrays, the copy's and the original's as h5py reads them
                    self.assertEqual(again["splits"][name][part].tobytes(), s[part].tobytes())
                    self.assertEqual(f[name][part][()].tobytes(), g[name][part][()].tobytes())
                    self.assertEqual(f[name][part][()].tobytes(), s[part].tobytes())
                    self.assertEqual(f[name][part].attrs["columns"], ",".join(s[part.lower() + "_columns"]))
                self.assertEqual(again["splits"][name]["t"] is None, "t" not in f[name])

    def test_new_dataset_from_numpy_and_its_checks(self):
        rng = np.random.default_rng(3)
        X, Y, t = rng.normal(size=(50, 2)), rng.normal(size=(50, 1)), np.arange(50) * 0.01
        out = os.path.join(self.dir, "mine.h5")
        spml.write_dataset(out, {"train": {"X": X, "Y": Y, "t": t, "x_columns": ["q:j", "qd:j"], "y_columns": ["tau:j"]},
                                 "test": {"X": X[:5], "Y": Y[:5], "x_columns": ["q:j", "qd:j"], "y_columns": ["tau:j"]}},
                           provenance={"generator": "a Python script"})
        back = spml.read_dataset(out)
        self.assertEqual(back["splits"]["train"]["t"].tobytes(), t.tobytes())
        self.assertIsNone(back["splits"]["test"]["t"])
        self.assertIsNone(back["model"])
        self.assertEqual(back["provenance"], {"generator": "a Python script"})
        # the library's checks apply, nothing is written, and no temporary is left
        bad = os.path.join(self.dir, "bad.h5")
        with self.assertRaisesRegex(ValueError, "bad.h5: group 'train': X has 50 rows but Y has 49"):
            spml.write_dataset(bad, {"train": {"X": X, "Y": Y[:49], "x_columns": ["a", "b"], "y_columns": ["y"]}})
        with self.assertRaisesRegex(ValueError, "column name 'a' appears twice"):
            spml.write_dataset(bad, {"train": {"X": X, "Y": Y, "x_columns": ["a", "a"], "y_columns": ["y"]}})
        with self.assertRaisesRegex(ValueError, "split 'train': X: expected a 2-D array, got 1-D"):
            spml.write_dataset(bad, {"train": {"X": t, "Y": Y, "x_columns": ["a"], "y_columns": ["y"]}})
        self.assertFalse(os.path.exists(bad))
        self.assertEqual([f for f in os.listdir(self.dir) if "tmp" in f], [])

    def test_bad_paths_are_named(self):
        missing = os.path.join(self.dir, "nowhere", "missing.h5")
        with self.assertRaisesRegex(FileNotFoundError, "missing.h5: no such file"):
            spml.read_dataset(missing)
        with self.assertRaisesRegex(FileNotFoundError, "missing.h5"):
            spml.parametric_model(missing)
        with self.assertRaisesRegex(FileNotFoundError, "missing.xml: no such MJCF file"):
            spml.regressor(os.path.join(self.dir, "missing.xml"))
        with self.assertRaisesRegex(FileNotFoundError, "missing.xml"):
            spml.identify(os.path.join(self.dir, "missing.xml"), self.toy)
        with self.assertRaisesRegex(FileNotFoundError, "missing.h5"):
            spml.diagnose(ARM, missing)
        with self.assertRaisesRegex(FileNotFoundError, "nowhere: no such learner library or folder"):
            spml.add_learner_path(os.path.dirname(missing))
        text = os.path.join(self.dir, "text.h5")
        with open(text, "w") as f:
            f.write("not HDF5\n")
        with self.assertRaisesRegex(ValueError, "text.h5: not an HDF5 file"):
            spml.read_dataset(text)
        with self.assertRaisesRegex(ValueError, "directory .*nowhere does not exist"):
            spml.write_dataset(missing, spml.read_dataset(self.toy)["splits"])
        os.remove(text)


class ToyRowsEqualBench(Fixture):
    """LLS and GP fitted from Python give `spml bench`'s predictions bit for bit, and the
    scores it prints in results.csv."""

    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        cls.bench = os.path.join(cls.dir, "bench")
        run("bench", "--data", cls.toy, "--out", cls.bench, "--learners", "LLS,GP", "--reps", "1", "--seed", "1")

    def test_lls_and_gp_reproduce_the_bench_rows(self):
        ds = spml.read_dataset(self.toy)
        train, test = ds["splits"]["train"], ds["splits"]["test_interp"]
        model = spml.parametric_model(self.toy)
        with open(os.path.join(self.bench, "results.csv")) as f:
            header, *lines = [line.rstrip("\n").split(",") for line in f]
        rows = {(r[header.index("algo")], r[header.index("split")]): r for r in lines}
        with h5py.File(os.path.join(self.bench, "predictions.h5"), "r") as p:
            self.assertEqual(p["test_interp/rows"][()][:, 0].tolist(), list(range(len(test["X"]))))
            for name in ("LLS", "GP"):
                learner = spml.Learner(name, seed=1).fit(train["X"], train["Y"], model=model)
                mean, std = learner.predict(test["X"], return_std=True)
                np.testing.assert_array_equal(mean, p[f"test_interp/{name}/rep0/mean"][()])
                if std is not None:
                    np.testing.assert_array_equal(std, p[f"test_interp/{name}/rep0/std"][()])
                scores = spml.score(test["Y"], mean, None if std is None else std**2)
                row = rows[(name, "test_interp")]
                self.assertEqual(f"{scores['rmse'][0]:.6g}", row[header.index("rmsemean")])
                self.assertAlmostEqual(np.sqrt(np.mean((test["Y"] - mean) ** 2)), scores["rmse"][0], delta=1e-12)
                if std is not None:
                    self.assertEqual(f"{scores['nllh'][0]:.6g}", row[header.index("nllhmean")])
        # the README's numbers (LLS Toy-Interp 1.34 against the paper's 1.29)
        self.assertEqual(rows[("LLS", "test_interp")][header.index("rmsemean")][:4], "1.34")

    def test_variances_are_positive_and_compositions_fit(self):
        ds = spml.read_dataset(self.toy)
        train, test = ds["splits"]["train"], ds["splits"]["test_extrap"]
        model = spml.parametric_model(ds)   # from the dict: the same model as from the file
        gp = spml.Learner("LLS-GP", seed=1, max_evals=200).fit(train["X"], train["Y"][:, 0], model=model)
        mean, std = gp.predict(test["X"], return_std=True)
        self.assertEqual(mean.shape, (len(test["X"]),))   # a 1-D Y gives 1-D predictions
        self.assertTrue(np.all(np.isfinite(std)) and np.all(std > 0))
        # the predictive std includes the noise: Toy's is 0.5 (0.53 fitted here); 20 % margin
        self.assertGreater(std.min(), 0.4)
        lls = spml.Learner("LLS").fit(train["X"], train["Y"], model=model)
        self.assertEqual(lls.predict(test["X"], return_std=True)[1], None)
        phi = model.phi(train["X"])
        np.testing.assert_allclose(lls.coef_, np.linalg.lstsq(phi, train["Y"][:, 0], rcond=None)[0], rtol=1e-9)
        # phi given directly instead of the model object: the same fit
        same = spml.Learner("LLS").fit(train["X"], train["Y"], phi=model.phi(train["X"]), param_names=model.param_names)
        np.testing.assert_array_equal(same.predict(test["X"], phi=model.phi(test["X"])), lls.predict(test["X"]))
        with self.assertRaisesRegex(ValueError, "learner 'SPGP' uses the parametric model: pass model="):
            spml.Learner("SPGP").fit(train["X"], train["Y"])
        with self.assertRaisesRegex(ValueError, "predict needs its phi"):
            same.predict(test["X"])


class EstimatorContract(unittest.TestCase):
    def test_learners_and_keys(self):
        names = spml.learners()
        for name in ("LLS", "GP", "SPGP", "SVR"):
            self.assertIn(name, names)
        self.assertIn("it-LLS-GP", spml.learners(compositions=True))
        keys = spml.learner_info("it-LLS-GP")["keys"]
        self.assertEqual(keys["iterations"]["default"], "3")
        self.assertEqual(keys["max_evals"]["type"], "integer")

    def test_sklearn_clone_get_set_params(self):
        from sklearn.base import clone
        gp = spml.Learner("GP", seed=7, max_evals=50, noise_floor=1e-5)
        params = gp.get_params()
        self.assertEqual(params["name"], "GP")
        self.assertEqual(params["seed"], 7)
        self.assertEqual(params["max_evals"], 50)
        self.assertIsNone(params["subset_rows"])   # unset: the learner's own default
        twin = clone(gp)
        self.assertIsNot(twin, gp)
        self.assertEqual(twin.get_params(), params)
        twin.set_params(max_evals=20, seed=8)
        self.assertEqual((twin.get_params()["max_evals"], twin.seed), (20, 8))
        self.assertEqual(gp.get_params()["max_evals"], 50)
        self.assertEqual(set(spml.Learner("it-LLS-GP").get_params()) - {"name", "seed"},
                         set(spml.learner_info("it-LLS-GP")["keys"]))
        with self.assertRaisesRegex(ValueError, "learner 'GP' has no config key 'C'"):
            gp.set_params(C=1.0)
        with self.assertRaisesRegex(ValueError, "GP: max_evals=0"):
            spml.Learner("GP", max_evals=0)
        with self.assertRaisesRegex(ValueError, "unknown learner 'Nope'"):
            spml.Learner("Nope")

    def test_cross_validation_with_sklearn(self):
        from sklearn.model_selection import GridSearchCV, cross_val_score
        rng = np.random.default_rng(1)
        X = rng.uniform(-2, 2, size=(90, 1))
        y = np.sin(2 * X[:, 0]) + 0.1 * rng.normal(size=90)
        # noise std 0.1 against a signal variance of about 0.5: R^2 near 1 - 0.01 / 0.5 = 0.98
        r2 = cross_val_score(spml.Learner("GP", max_evals=100), X, y, cv=3)
        self.assertTrue(np.all(r2 > 0.9), r2)   # 0.957-0.978 measured
        search = GridSearchCV(spml.Learner("GP"), {"max_evals": [2, 100]}, cv=3).fit(X, y)
        self.assertEqual(search.best_params_, {"max_evals": 100})
        import pickle
        self.assertEqual(pickle.loads(pickle.dumps(spml.Learner("GP", max_evals=3))).get_params()["max_evals"], 3)
        with self.assertRaisesRegex(TypeError, "a fitted spml.Learner .GP. cannot be pickled"):
            pickle.dumps(search.best_estimator_)

    def test_same_seed_same_numbers(self):
        rng = np.random.default_rng(0)
        X = rng.uniform(-2, 2, size=(60, 1))
        Y = np.sin(2 * X) + 0.1 * rng.normal(size=X.shape)
        a = spml.Learner("GP", seed=4).fit(X, Y).predict(X)
        b = spml.Learner("GP", seed=4).fit(X, Y).predict(X)
        np.testing.assert_array_equal(a, b)
        self.assertLess(np.sqrt(np.mean((a - np.sin(2 * X)) ** 2)), 0.1)   # within the noise std
        if "BNN" in spml.learners():   # a learner that draws random numbers: the seed decides them
            bnn = [spml.Learner("BNN", seed=s, steps=100).fit(X, Y).predict(X) for s in (4, 4, 5)]
            np.testing.assert_array_equal(bnn[0], bnn[1])
            self.assertFalse(np.array_equal(bnn[0], bnn[2]))


class ModelsIdentifyDiagnose(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.gl = os.path.join(cls.tmp.name, "gl.h5")
        run("generate", "--scenario", "simdyn-gl", "--test-stride", "10", "--out", cls.gl, "--quiet")

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_regressor_and_identify_equal_the_commands(self):
        r = spml.regressor(ARM)
        cli = json.loads(run("regressor", "--model", ARM, "--json"))
        self.assertEqual(r["rank"], 17)   # the paper's 17 regrouped coefficients
        for key in ("standard_parameters", "rank", "names"):
            self.assertEqual(r[key], cli[key])
        self.assertEqual(r["prior"].tolist(), cli["prior"])
        for key in ("method", "tolerance", "smallest_kept", "largest_dropped", "ratio", "close_call"):
            self.assertEqual(r["rank_decision"][key], cli["rank_decision"][key])
        self.assertEqual(len(r["standard_names"]), len(r["standard_values"]))
        ident = spml.identify(ARM, self.gl)
        cli = json.loads(run("identify", "--model", ARM, "--data", self.gl, "--json"))
        for key in ("names", "sigma", "condition_number", "errors"):
            self.assertEqual(ident[key], cli[key])
        for key in ("estimate", "std_error", "prior"):
            self.assertEqual(ident[key].tolist(), cli[key])
        # LLS on the MJCF's regressor (the model by path, as bench --model) is the same least
        # squares: equal up to the two solvers' rounding (3.5e-13 measured)
        model = spml.parametric_model(self.gl, mjcf=ARM)
        self.assertEqual(model.param_names, ident["names"])
        train = spml.read_dataset(self.gl)["splits"]["train"]
        lls = spml.Learner("LLS").fit(train["X"], train["Y"], model=model)
        np.testing.assert_allclose(lls.coef_, ident["estimate"], rtol=1e-9)

    def test_diagnose_names_the_hidden_band(self):
        out = os.path.join(self.tmp.name, "diag")
        os.mkdir(out)
        report = spml.diagnose(ARM, self.gl, out=out, rollouts=2)
        with open(os.path.join(out, "report.json")) as f:
            self.assertEqual(json.load(f), report)
        first = report["causes"][0]
        self.assertEqual((first["effect"], first["joints"]), ("friction_band", ["joint0"]))
        # injected: band [0.15, 0.25] on joint0 (spml generate's simdyn-gl)
        self.assertAlmostEqual(first["shape"]["lower"], 0.15, delta=0.005)
        self.assertAlmostEqual(first["shape"]["upper"], 0.25, delta=0.005)
        self.assertLess(report["final"]["rel_error_test_all"], 0.5 * report["baseline"]["rel_error_test_all"])
        with self.assertRaisesRegex(ValueError, "min_gain = 2: must be a finite number in \\[0, 1\\]"):
            spml.diagnose(ARM, self.gl, min_gain=2.0)


class Installed(unittest.TestCase):
    def test_installed_module_finds_the_installed_learners(self):
        build = os.environ["SPML_BUILD_DIR"]
        with tempfile.TemporaryDirectory() as prefix:
            cmake = os.environ.get("SPML_CMAKE", "cmake")
            subprocess.run([cmake, "--install", build, "--prefix", prefix, "--component", "spml_runtime"],
                           check=True, capture_output=True)
            env = dict(os.environ, PYTHONPATH=os.path.join(prefix, "lib", "python3", "dist-packages"))
            env.pop("SPML_LEARNER_PATH", None)
            out = subprocess.run(["/usr/bin/python3", "-c",
                                  "import spml; print(spml.__file__); print(spml.learner_info('GP')['files'][0])"],
                                 check=True, capture_output=True, text=True, env=env, cwd=prefix).stdout.split("\n")
            self.assertTrue(out[0].startswith(prefix), out)
            self.assertTrue(out[1].startswith(prefix), out)


if __name__ == "__main__":
    print("python", sys.version.split()[0], "at", sys.executable, "; spml", spml.__version__, "from", spml.__file__)
    unittest.main(verbosity=2)
