// Excitation references. The multi-sine follows the usual identification practice of a few
// sines per joint with random frequencies and phases in a band (Swevers et al. 1997 use
// optimised Fourier series; random ones suffice for a generator); the chirp sweeps the same band.
#include "spml/envs/excitation.h"

#include <algorithm>
#include <random>
#include <stdexcept>

#include "signals.h"
#include "spml/envs/mujoco_model.h"
#include "spml/import.h"
#include "spml/signal.h"

namespace spml {
namespace {

constexpr int kSines = 4;   // components per joint in the multi-sine

// Centre and peak excursion of joint j's reference.
std::pair<double, double> joint_span(const mjModel* m, int j, double amplitude) {
  const bool slide = m->jnt_type[j] == mjJNT_SLIDE;
  double centre = m->qpos0[m->jnt_qposadr[j]], a = slide ? amplitude / 8 : amplitude;
  if (m->jnt_limited[j]) {
    const double lo = m->jnt_range[2 * j], hi = m->jnt_range[2 * j + 1];
    centre = 0.5 * (lo + hi);
    a = std::min(a, 0.4 * (hi - lo));
  }
  return {centre, a};
}

Eigen::MatrixXd file_reference(const mjModel* m, const std::string& path, const Eigen::VectorXd& times) {
  const Table table = read_csv_table(path);
  auto column = [&](const std::string& name) -> const Eigen::VectorXd& {
    for (size_t i = 0; i < table.names.size(); ++i)
      if (table.names[i] == name) return table.columns[i];
    throw std::runtime_error(path + ": excitation file has no column '" + name + "'");
  };
  const Eigen::VectorXd& t = column("t");
  if (t.size() < 2) throw std::runtime_error(path + ": excitation file needs at least two rows");
  for (Eigen::Index i = 1; i < t.size(); ++i)
    if (!(t[i] > t[i - 1])) throw std::runtime_error(path + ": column 't' must increase; row " + std::to_string(i + 1) + " does not");
  const auto names = joint_names(m, path);
  Eigen::MatrixXd q(times.size(), m->njnt);
  // The file's time axis starts where the simulation does.
  const Eigen::VectorXd at = times.array() + t[0];
  for (int j = 0; j < m->njnt; ++j) q.col(j) = interpolate(t, column("q:" + names[static_cast<size_t>(j)]), at);
  return q;
}

Eigen::MatrixXd synthetic_reference(const mjModel* m, const ExcitationOptions& o, const Eigen::VectorXd& times) {
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> freq(o.f_low, o.f_high), phase(0, 2 * M_PI);
  const bool chirp = o.kind == "chirp";
  const double duration = times.size() ? std::max(times[times.size() - 1], 1e-9) : 1.0;
  const signals::Chirp sweep{o.f_low, o.f_high, duration};
  Eigen::MatrixXd q(times.size(), m->njnt);
  for (int j = 0; j < m->njnt; ++j) {
    const auto [centre, a] = joint_span(m, j, o.amplitude);
    double w[kSines], p[kSines];
    for (int k = 0; k < kSines; ++k) w[k] = 2 * M_PI * freq(rng), p[k] = phase(rng);
    for (Eigen::Index i = 0; i < times.size(); ++i) {
      double v = 0;
      if (chirp) {
        v = a * std::sin(sweep.phase(times[i]) + p[0]);
      } else {
        for (int k = 0; k < kSines; ++k) v += a / kSines * std::sin(w[k] * times[i] + p[k]);
      }
      q(i, j) = centre + v;
    }
  }
  return q;
}

}  // namespace

std::vector<std::string> joint_names(const mjModel* m, const std::string& source) {
  std::vector<std::string> names;
  for (int j = 0; j < m->njnt; ++j) {
    const char* n = mj_id2name(m, mjOBJ_JOINT, j);
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)
      throw std::runtime_error(source + ": " + joint_description(m, j) + " is a ball or free joint; only hinge and slide joints can be measured");
    if (!n || !*n) throw std::runtime_error(source + ": " + joint_description(m, j) + " has no name; every joint needs one for the data columns");
    names.emplace_back(n);
  }
  return names;
}

double reference_file_duration(const std::string& path) {
  const Table table = read_csv_table(path);
  for (size_t i = 0; i < table.names.size(); ++i)
    if (table.names[i] == "t" && table.columns[i].size() > 1) return table.columns[i][table.columns[i].size() - 1] - table.columns[i][0];
  throw std::runtime_error(path + ": excitation file has no column 't' with two or more rows");
}

ReferenceTrack make_reference(const mjModel* m, const ExcitationOptions& o, const Eigen::VectorXd& times) {
  ReferenceTrack r;
  if (!(o.f_low > 0 && o.f_high >= o.f_low)) throw std::runtime_error("excitation band must satisfy 0 < f_low <= f_high");
  if (o.kind.rfind("file:", 0) == 0)
    r.q = file_reference(m, o.kind.substr(5), times);
  else if (o.kind == "multisine" || o.kind == "chirp")
    r.q = synthetic_reference(m, o, times);
  else
    throw std::runtime_error("excitation '" + o.kind + "': choose multisine, chirp or file:PATH");
  const double dt = times.size() > 1 ? times[1] - times[0] : 1.0;
  r.qd.resize(r.q.rows(), r.q.cols());
  r.qdd.resize(r.q.rows(), r.q.cols());
  for (Eigen::Index j = 0; j < r.q.cols(); ++j) {
    r.qd.col(j) = central_difference(r.q.col(j), dt);
    r.qdd.col(j) = central_difference(r.qd.col(j), dt);
  }
  return r;
}

}  // namespace spml
