#include "identify_consistent.h"

#include "commands.h"

#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "spml/envs/consistent_identification.h"
#include "spml/envs/identified_model.h"
#include "spml/matrix_file.h"

namespace spml::cli {
namespace {

template <class V>
std::vector<double> vec(const V& v) { return {v.data(), v.data() + v.size()}; }

nlohmann::json inertial_json(const BodyInertial& b) {
  const auto full = b.fullinertia();
  return {{"mass", b.mass}, {"com", vec(b.com)}, {"fullinertia", std::vector<double>(full.begin(), full.end())},
          {"principal", vec(b.principal)},
          {"quat", {b.orientation.w(), b.orientation.x(), b.orientation.y(), b.orientation.z()}}};
}

nlohmann::json to_json(const ConsistentArgs& a, const ConsistentIdentification& id, const std::optional<Identification>& ls) {
  nlohmann::json j{{"model", a.model}, {"data", a.data}, {"split", a.split}, {"estimator", "consistent"},
                   {"prior_weight", id.prior_weight}, {"sigma", id.sigma}, {"rank", id.rank}, {"evaluations", id.evaluations},
                   {"seconds", id.seconds}, {"stop", id.stop}, {"bodies", nlohmann::json::array()}, {"terms", nlohmann::json::array()}};
  for (const auto& b : id.bodies) {
    nlohmann::json e{{"name", b.name}, {"fitted", b.fitted}, {"identified", inertial_json(b.identified)},
                     {"prior", inertial_json(b.prior)}, {"max_z", b.max_z}, {"changed", b.changed}};
    e["std_error"] = {{"mass", b.std_error[0]}, {"com", vec(b.std_error.segment<3>(1))}, {"fullinertia", vec(b.std_error.tail<6>())}};
    if (!b.note.empty()) e["note"] = b.note;
    j["bodies"].push_back(e);
  }
  for (const auto& t : id.terms)
    j["terms"].push_back({{"name", t.name}, {"value", t.value}, {"std_error", t.std_error}, {"prior", t.prior},
                          {"fitted", t.fitted}, {"at_bound", t.at_bound}});
  for (const auto& e : id.errors) j["errors"].push_back({{"split", e.split}, {"rows", e.rows}, {"relative_error", e.relative_error}, {"rmse", e.rmse}});
  if (ls)
    for (const auto& e : ls->errors)
      j["least_squares_errors"].push_back({{"split", e.split}, {"rows", e.rows}, {"relative_error", e.relative_error}, {"rmse", e.rmse}});
  return j;
}

std::string triple(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << std::setprecision(4) << v.x() << " " << v.y() << " " << v.z();
  return s.str();
}

void print(const ConsistentArgs& a, const ConsistentIdentification& id, const std::optional<Identification>& ls) {
  std::cout << "identified on '" << a.split << "' of " << a.data << ": physically consistent (log-Cholesky bodies, joint terms >= 0, "
            << "prior weight " << id.prior_weight << "), residual std " << id.sigma << ", " << id.evaluations << " evaluations, "
            << id.seconds << " s (" << id.stop << ")\n";
  if (id.stop != "CONVERGED")
    std::cout << "warning: the optimiser stopped before converging (" << id.stop << "): the estimates may still move\n";
  for (const auto& b : id.bodies) {
    if (!b.fitted) {
      std::cout << "  body " << b.name << "  " << b.note << "\n";
      continue;
    }
    std::cout << "  body " << b.name << (b.changed ? "  CHANGED" : "") << "  (largest |change| / SE " << std::setprecision(3) << b.max_z
              << ")\n" << std::setprecision(6);
    std::cout << "      mass " << b.prior.mass << " -> " << b.identified.mass << " +- " << b.std_error[0] << " kg\n"
              << "      com  " << triple(b.prior.com) << " -> " << triple(b.identified.com) << " +- " << triple(b.std_error.segment<3>(1)) << " m\n"
              << "      principal moments " << triple(b.prior.principal) << " -> " << triple(b.identified.principal) << " kg m^2\n";
  }
  for (const auto& t : id.terms)
    std::cout << "  " << std::setw(24) << std::left << t.name << std::right << " " << std::setw(12) << t.prior << " -> " << std::setw(12)
              << t.value << " +- " << t.std_error << (t.at_bound ? "  (at its bound 0)" : "") << (t.fitted ? "" : "  (not seen: kept)") << "\n";
  for (size_t i = 0; i < id.errors.size(); ++i)
    std::cout << "  " << (i == 0 ? "fit      " : "held out ") << id.errors[i].split << ": relative error " << 100 * id.errors[i].relative_error
              << " %" << (ls ? " (least squares on base parameters: " + std::to_string(100 * ls->errors[i].relative_error) + " %)" : "")
              << ", RMSE " << id.errors[i].rmse << "\n";
}

// Writes the identified model and checks that MuJoCo compiles it to the identified parameters.
std::vector<std::string> write_model(const ConsistentArgs& a, const MjcfRegressor& reg, const ConsistentIdentification& id) {
  std::vector<std::string> notes;
  const MjcfEdits edits = identified_model_edits(reg, id, notes);
  MjcfEdits with_comment = edits;
  with_comment.comment = "identified by spml identify --estimator consistent from " + a.data + " (split '" + a.split + "')";
  write_text_atomic(a.write_model, edit_mjcf(a.model, with_comment, notes));
  const MjcfRegressor written(a.write_model, RegressorOptions{a.offsets});
  const Eigen::VectorXd& got = written.model_params();
  for (const auto& b : id.bodies) {
    const bool written_body = std::any_of(edits.inertials.begin(), edits.inertials.end(), [&](const auto& in) { return in.body == b.name; });
    if (!b.fitted || !written_body) continue;
    const auto at = 10 * static_cast<Eigen::Index>(b.body_id - 1);
    if (got.size() != id.pi.size() || (got.segment<10>(at) - id.pi.segment<10>(at)).norm() > 1e-6 * id.pi.segment<10>(at).norm()) {
      std::filesystem::remove(a.write_model);
      throw std::runtime_error(a.write_model + ": MuJoCo compiles body '" + b.name + "' of the written model to other parameters "
                               "than identified (a compiler setting of " + a.model + "?); the file is not kept");
    }
  }
  return notes;
}

}  // namespace

void identify_consistent_command(const ConsistentArgs& a) {
  const MjcfRegressor reg(a.model, RegressorOptions{a.offsets});
  warn_inverse_mismatches(reg, a.model);
  const Dataset ds = read_dataset(a.data);
  // Least squares on base parameters, for comparison; it fails where the data leave a base
  // parameter free, which the consistent fit takes from the prior.
  std::optional<Identification> ls;
  std::string ls_failure;
  try {
    ls = identify(reg, reg.base_parameters(), ds, a.split);
  } catch (const DatasetError& e) {
    ls_failure = e.what();
  }
  ConsistentOptions o;
  o.prior_weight = a.prior_weight;
  const ConsistentIdentification id = identify_consistent(reg, ds, a.split, o);
  std::vector<std::string> notes;
  if (!a.write_model.empty()) notes = write_model(a, reg, id);
  if (a.json) {
    nlohmann::json j = to_json(a, id, ls);
    if (!a.write_model.empty()) j["written_model"] = a.write_model;
    j["notes"] = notes;
    if (!ls) j["least_squares_failure"] = ls_failure;
    std::cout << json_output(j, a.model);
    return;
  }
  print(a, id, ls);
  if (!ls) std::cout << "least squares on base parameters failed: " << ls_failure << "\n";
  if (!a.write_model.empty()) std::cout << "written: " << a.write_model << "\n";
  for (const auto& n : notes) std::cout << "note: " << n << "\n";
}

}  // namespace spml::cli
