#include "spml/learners/evaluate.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "spml/envs/parametric_model.h"
#include "spml/matrix_file.h"

namespace spml {

namespace fs = std::filesystem;

Scores score(const LearnerMatrix& Y, const LearnerPrediction& p) {
  Scores s;
  const double n = static_cast<double>(Y.rows());
  for (Eigen::Index o = 0; o < Y.cols(); ++o) {
    const Eigen::ArrayXd err = (Y.col(o) - p.mean.col(o)).array();
    s.rmse.push_back(std::sqrt(err.square().sum() / n));
    if (p.var.size() == 0) {
      s.nllh.push_back(std::numeric_limits<double>::infinity());
    } else {
      const Eigen::ArrayXd v = p.var.col(o).array();
      s.nllh.push_back((0.5 * (2.0 * M_PI * v).log() + 0.5 * err.square() / v).sum() / n);
    }
  }
  return s;
}

Summary summarize(const std::vector<double>& values) {
  Summary s;
  if (values.empty()) return s;
  s.min = *std::min_element(values.begin(), values.end());
  s.max = *std::max_element(values.begin(), values.end());
  if (std::isinf(s.max) || std::isinf(s.min)) {
    // Without a variance the NLLH is +inf in every repetition: report inf, not NaN.
    s.mean = s.max;
    s.std = 0.0;
    return s;
  }
  double sum = 0;
  for (double v : values) sum += v;
  s.mean = sum / static_cast<double>(values.size());
  double sq = 0;
  for (double v : values) sq += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(sq / static_cast<double>(values.size()));
  return s;
}

std::vector<Eigen::Index> strided_rows(Eigen::Index rows, Eigen::Index max) {
  const Eigen::Index stride = max > 0 && rows > max ? (rows + max - 1) / max : 1;
  std::vector<Eigen::Index> idx;
  for (Eigen::Index i = 0; i < rows; i += stride) idx.push_back(i);
  return idx;
}

namespace {

LearnerMatrix take_rows(const RowMatrix& m, const std::vector<Eigen::Index>& rows) {
  LearnerMatrix out(static_cast<Eigen::Index>(rows.size()), m.cols());
  for (size_t i = 0; i < rows.size(); ++i) out.row(static_cast<Eigen::Index>(i)) = m.row(rows[i]);
  return out;
}

// One split as the learners see it.
struct Part {
  std::string name;
  std::vector<Eigen::Index> rows;
  LearnerMatrix X, Y, phi;
  bool has_phi = false;
  LearnerData data(bool with_y) const {
    LearnerData d;
    d.X = &X;
    d.Y = with_y ? &Y : nullptr;
    d.phi = has_phi ? &phi : nullptr;
    d.outputs = static_cast<int>(Y.cols());
    return d;
  }
};

std::string fmt(double v) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  std::ostringstream s;
  s << std::setprecision(6) << v;
  return s.str();
}

std::string unit_path(const std::string& out, const std::string& algo, int rep) {
  return (fs::path(out) / "units" / algo / ("rep" + std::to_string(rep) + ".h5")).string();
}

std::string scenario_name(const Dataset& ds, const std::string& file) {
  auto it = ds.provenance.find("scenario");
  return it != ds.provenance.end() ? it->second : fs::path(file).stem().string();
}

// What a rerun must agree on to reuse finished units.
nlohmann::json manifest(const BenchOptions& o, const Dataset& ds, const std::vector<Part>& parts) {
  nlohmann::json m;
  m["format"] = "spml-bench/1";
  m["data"] = fs::absolute(o.data).string();
  m["data_bytes"] = fs::file_size(o.data);
  m["scenario"] = scenario_name(ds, o.data);
  m["seed"] = o.seed;
  m["train_max"] = o.train_max;
  m["test_max"] = o.test_max;
  nlohmann::json cfg = nlohmann::json::object();
  for (const auto& [k, v] : o.config.values) cfg[k] = v;
  m["config"] = cfg;
  for (const Part& p : parts) m["rows"][p.name] = p.rows.size();
  return m;
}

}  // namespace

BenchReport run_bench(const LearnerRegistry& registry, const BenchOptions& o, bool all_requested) {
  auto log = [&](const std::string& s) {
    if (o.log) o.log(s);
  };
  if (o.reps < 1) throw LearnerError("--reps must be >= 1");
  const Dataset ds = read_dataset(o.data);
  const Split& train_split = ds.get("train");
  std::unique_ptr<ParametricModel> model;
  std::string model_problem;
  try {
    model = make_parametric_model(ds, train_split);
  } catch (const std::exception& e) {
    model_problem = e.what();
  }

  // Which learners can run here; "all" quietly leaves out what the data cannot support.
  BenchReport report;
  std::vector<std::string> learners;
  std::map<std::string, std::uint32_t> flags;
  for (const auto& name : o.learners) {
    const std::uint32_t f = registry.create(name)->flags();
    std::string why;
    if ((f & SPML_LEARNER_USES_MODEL) && !model) why = "needs a parametric model: " + model_problem;
    else if ((f & SPML_LEARNER_NEEDS_TRUTH) && ds.model.truth.size() == 0) why = "the dataset has no true coefficients";
    else if ((f & SPML_LEARNER_NEEDS_PRIOR) && ds.model.prior.size() == 0) why = "the dataset has no prior coefficients";
    if (why.empty()) {
      learners.push_back(name);
      flags[name] = f;
    } else if (all_requested) {
      report.skipped.push_back(name + ": " + why);
    } else {
      throw LearnerError("learner '" + name + "' cannot run on " + o.data + ": " + why);
    }
  }
  // Reject config keys no selected learner understands (a typo must not pass silently).
  for (const auto& [k, v] : o.config.values) {
    bool used = false;
    for (const auto& name : learners) used |= registry.config_keys(name).count(k) > 0;
    if (!used) throw LearnerError("config key '" + k + "' is not accepted by any selected learner");
  }

  std::vector<Part> parts;
  auto make_part = [&](const Split& s, Eigen::Index max) {
    Part p;
    p.name = s.name;
    p.rows = strided_rows(s.rows(), max);
    p.X = take_rows(s.X, p.rows);
    p.Y = take_rows(s.Y, p.rows);
    if (model) {
      p.phi = model->stacked(p.X);
      p.has_phi = true;
    }
    return p;
  };
  parts.push_back(make_part(train_split, o.train_max));
  for (const Split& s : ds.splits)
    if (s.name != "train" && s.name.rfind("test", 0) == 0) parts.push_back(make_part(s, o.test_max));
  if (parts.size() < 2) throw LearnerError(o.data + ": no test split (a group named test*)");
  const Part& train = parts.front();

  LearnerModel lm;
  lm.names = ds.model.param_names;
  lm.prior = ds.model.prior;
  lm.truth = ds.model.truth;

  fs::create_directories(o.out);
  const nlohmann::json m = manifest(o, ds, parts);
  const std::string manifest_path = (fs::path(o.out) / "bench.json").string();
  if (fs::exists(manifest_path)) {
    nlohmann::json old;
    try {
      std::ifstream(manifest_path) >> old;
    } catch (const std::exception& e) {
      throw LearnerError(manifest_path + ": unreadable (" + e.what() + "); remove the folder or choose another --out");
    }
    for (const auto& [key, value] : m.items())
      if (old.value(key, nlohmann::json()) != value)
        throw LearnerError(o.out + " holds results of another run (" + key + ": " + old.value(key, nlohmann::json()).dump() +
                           " vs " + value.dump() + "); choose another --out or remove it");
  } else {
    write_text_atomic(manifest_path, m.dump(2) + "\n");
  }

  const std::string scenario = scenario_name(ds, o.data);
  std::ostringstream head;
  head << scenario << ": train " << train.rows.size() << " of " << train_split.rows() << " rows";
  for (size_t i = 1; i < parts.size(); ++i) head << ", " << parts[i].name << " " << parts[i].rows.size() << " rows";
  log(head.str());

  // Run the missing units.
  for (size_t li = 0; li < learners.size(); ++li) {
    const std::string& name = learners[li];
    auto learner = registry.create(name);
    const int fits = (flags[name] & SPML_LEARNER_DETERMINISTIC) ? 1 : o.reps;
    for (int rep = 0; rep < fits; ++rep) {
      const std::string path = unit_path(o.out, name, rep);
      std::ostringstream tag;
      tag << "[" << li + 1 << "/" << learners.size() << "] " << name << " rep " << rep + 1 << "/" << fits;
      if (fs::exists(path)) {
        ++report.units_cached;
        log(tag.str() + ": done earlier");
        continue;
      }
      log(tag.str() + ": fitting on " + std::to_string(train.rows.size()) + " rows ...");
      LearnerConfig config = o.config;
      config.seed = o.seed + static_cast<std::uint64_t>(rep);
      MatrixFile unit;
      try {
        const auto t0 = std::chrono::steady_clock::now();
        learner->fit(train.data(true), lm, config);
        const auto t1 = std::chrono::steady_clock::now();
        std::ostringstream summary;
        for (size_t pi = 1; pi < parts.size(); ++pi) {
          LearnerPrediction pred = learner->predict(parts[pi].data(false));
          if (!pred.mean.allFinite()) throw LearnerError(name + ": non-finite predictive mean on " + parts[pi].name);
          if (pred.var.size() && !(pred.var.array() > 0).all())
            throw LearnerError(name + ": predictive variance not positive and finite on " + parts[pi].name);
          unit.matrices[parts[pi].name + "/mean"] = pred.mean;
          if (pred.var.size()) unit.matrices[parts[pi].name + "/var"] = pred.var;
          const Scores sc = score(parts[pi].Y, pred);
          summary << " " << parts[pi].name << " RMSE";
          for (double r : sc.rmse) summary << " " << fmt(r);
        }
        const auto t2 = std::chrono::steady_clock::now();
        const Eigen::VectorXd coef = learner->coefficients();
        if (coef.size()) unit.matrices["coefficients"] = LearnerMatrix(coef.transpose());
        unit.attributes["learner"] = name;
        unit.attributes["notes"] = learner->notes();
        unit.attributes["fit_seconds"] = fmt(std::chrono::duration<double>(t1 - t0).count());
        unit.attributes["predict_seconds"] = fmt(std::chrono::duration<double>(t2 - t1).count());
        fs::create_directories(fs::path(path).parent_path());
        write_matrix_file(path, unit);
        ++report.units_run;
        log(tag.str() + ": " + unit.attributes["fit_seconds"] + " s;" + summary.str() +
            (learner->notes().empty() ? "" : "  [" + learner->notes() + "]"));
      } catch (const std::exception& e) {
        report.failed.push_back(name + ": " + e.what());
        log(tag.str() + ": FAILED: " + e.what());
        break;
      }
    }
  }

  // Aggregate every finished unit of the selected learners into results.csv / predictions.h5.
  std::ostringstream csv;
  csv << "scenario,split,output,algo,rmsemean,rmsestd,rmsemin,rmsemax,nllhmean,nllhstd,nllhmin,nllhmax,fits,fitsec,"
         "warnings\n";
  MatrixFile predictions;
  predictions.attributes["format"] = "spml-predictions/1";
  predictions.attributes["data"] = fs::absolute(o.data).string();
  predictions.attributes["scenario"] = scenario;
  for (size_t pi = 1; pi < parts.size(); ++pi) {
    predictions.matrices[parts[pi].name + "/y"] = parts[pi].Y;
    LearnerMatrix rows(static_cast<Eigen::Index>(parts[pi].rows.size()), 1);
    for (size_t i = 0; i < parts[pi].rows.size(); ++i) rows(static_cast<Eigen::Index>(i), 0) = static_cast<double>(parts[pi].rows[i]);
    predictions.matrices[parts[pi].name + "/rows"] = rows;
  }
  for (const auto& name : learners) {
    std::vector<MatrixFile> units;
    for (int rep = 0; rep < o.reps; ++rep) {
      const std::string path = unit_path(o.out, name, rep);
      if (fs::exists(path)) units.push_back(read_matrix_file(path));
    }
    if (units.empty()) continue;
    const bool deterministic = flags[name] & SPML_LEARNER_DETERMINISTIC;
    // A deterministic learner is fitted once; its repetitions are that fit by construction.
    if (!deterministic && static_cast<int>(units.size()) < o.reps) continue;   // incomplete: rerun finishes it
    double fitsec = 0;
    std::string warnings;
    for (const auto& u : units) {
      fitsec += std::stod(u.attributes.at("fit_seconds"));
      const std::string& n = u.attributes.count("notes") ? u.attributes.at("notes") : std::string();
      if (!n.empty() && warnings.find(n) == std::string::npos) warnings += (warnings.empty() ? "" : " | ") + n;
    }
    fitsec /= static_cast<double>(units.size());
    std::replace(warnings.begin(), warnings.end(), ',', ';');
    std::replace(warnings.begin(), warnings.end(), '\n', ' ');
    for (size_t pi = 1; pi < parts.size(); ++pi) {
      const Part& part = parts[pi];
      std::vector<std::vector<double>> rmse(static_cast<size_t>(part.Y.cols())), nllh(rmse.size());
      for (size_t r = 0; r < static_cast<size_t>(o.reps); ++r) {
        const MatrixFile& u = units[deterministic ? 0 : r];
        LearnerPrediction p;
        p.mean = u.matrices.at(part.name + "/mean");
        if (u.matrices.count(part.name + "/var")) p.var = u.matrices.at(part.name + "/var");
        const Scores sc = score(part.Y, p);
        for (size_t k = 0; k < rmse.size(); ++k) {
          rmse[k].push_back(sc.rmse[k]);
          nllh[k].push_back(sc.nllh[k]);
        }
        if (!deterministic || r == 0) {
          const std::string key = part.name + "/" + name + "/rep" + std::to_string(r);
          predictions.matrices[key + "/mean"] = p.mean;
          if (p.var.size()) predictions.matrices[key + "/std"] = p.var.cwiseSqrt();
        }
      }
      for (size_t k = 0; k < rmse.size(); ++k) {
        const Summary a = summarize(rmse[k]), b = summarize(nllh[k]);
        csv << scenario << "," << part.name << "," << k << "," << name << "," << fmt(a.mean) << "," << fmt(a.std)
            << "," << fmt(a.min) << "," << fmt(a.max) << "," << fmt(b.mean) << "," << fmt(b.std) << ","
            << fmt(b.min) << "," << fmt(b.max) << "," << units.size() << "," << fmt(fitsec) << "," << warnings
            << "\n";
      }
    }
  }
  write_text_atomic((fs::path(o.out) / "results.csv").string(), csv.str());
  write_matrix_file((fs::path(o.out) / "predictions.h5").string(), predictions);
  return report;
}

}  // namespace spml
