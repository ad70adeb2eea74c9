// spml info FILE [--json]: what a dataset holds, with per-column statistics.
#include <cmath>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "spml/dataset.h"

namespace spml::cli {
namespace {

nlohmann::json column_stats(const RowMatrix& m, const std::vector<std::string>& names) {
  nlohmann::json cols = nlohmann::json::array();
  for (Eigen::Index c = 0; c < m.cols(); ++c) {
    auto v = m.col(c);
    double mean = v.mean();
    double sd = m.rows() > 1 ? std::sqrt((v.array() - mean).square().sum() / static_cast<double>(m.rows() - 1)) : 0.0;
    cols.push_back({{"name", names[c]}, {"min", v.minCoeff()}, {"max", v.maxCoeff()}, {"mean", mean}, {"std", sd}});
  }
  return cols;
}

nlohmann::json describe(const std::string& path, const Dataset& ds) {
  nlohmann::json j;
  j["file"] = path;
  j["format"] = kFormatName;
  j["provenance"] = ds.provenance;
  for (const Split& s : ds.splits) {
    nlohmann::json sj;
    sj["name"] = s.name;
    sj["rows"] = s.rows();
    sj["X"] = {{"shape", {s.X.rows(), s.X.cols()}}, {"columns", column_stats(s.X, s.x_columns)}};
    sj["Y"] = {{"shape", {s.Y.rows(), s.Y.cols()}}, {"columns", column_stats(s.Y, s.y_columns)}};
    if (s.t.size()) sj["t"] = {{"start", s.t[0]}, {"end", s.t[s.t.size() - 1]}};
    j["splits"].push_back(sj);
  }
  if (!ds.model.empty()) {
    const ModelInfo& m = ds.model;
    nlohmann::json mj{{"name", m.name}, {"param_names", m.param_names}};
    if (m.prior.size()) mj["prior"] = std::vector<double>(m.prior.data(), m.prior.data() + m.prior.size());
    if (m.truth.size()) mj["truth"] = std::vector<double>(m.truth.data(), m.truth.data() + m.truth.size());
    if (!m.mjcf_path.empty()) mj["mjcf_path"] = m.mjcf_path;
    mj["mjcf_inline"] = !m.mjcf_xml.empty();
    j["model"] = mj;
  }
  return j;
}

void print_text(const nlohmann::json& j) {
  std::cout << j["file"].get<std::string>() << "  (format " << j["format"].get<std::string>() << ")\n";
  for (auto& [k, v] : j["provenance"].items()) std::cout << "  " << k << ": " << v.get<std::string>() << "\n";
  for (const auto& s : j["splits"]) {
    std::cout << "\nsplit '" << s["name"].get<std::string>() << "': " << s["rows"] << " rows";
    if (s.contains("t")) std::cout << ", t = " << s["t"]["start"] << " .. " << s["t"]["end"] << " s";
    std::cout << "\n";
    for (const char* part : {"X", "Y"}) {
      std::cout << "  " << part << " [" << s[part]["shape"][0] << " x " << s[part]["shape"][1] << "]\n";
      std::cout << "    " << std::left << std::setw(20) << "column" << std::right << std::setw(13) << "min"
                << std::setw(13) << "max" << std::setw(13) << "mean" << std::setw(13) << "std" << "\n";
      for (const auto& c : s[part]["columns"]) {
        std::cout << "    " << std::left << std::setw(20) << c["name"].get<std::string>() << std::right;
        for (const char* k : {"min", "max", "mean", "std"})
          std::cout << std::setw(13) << std::setprecision(5) << c[k].get<double>();
        std::cout << "\n";
      }
    }
  }
  if (j.contains("model")) {
    const auto& m = j["model"];
    std::cout << "\nmodel '" << m["name"].get<std::string>() << "': " << m["param_names"].size() << " parameters";
    if (m.contains("mjcf_path")) std::cout << ", MJCF " << m["mjcf_path"].get<std::string>();
    std::cout << "\n";
    for (size_t i = 0; i < m["param_names"].size(); ++i) {
      std::cout << "    " << std::left << std::setw(28) << m["param_names"][i].get<std::string>() << std::right;
      if (m.contains("prior")) std::cout << " prior " << std::setw(10) << m["prior"][i].get<double>();
      if (m.contains("truth")) std::cout << " truth " << std::setw(10) << m["truth"][i].get<double>();
      std::cout << "\n";
    }
  }
}

}  // namespace

void add_info(CLI::App& app) {
  auto* cmd = app.add_subcommand("info", "Show the splits, shapes, columns and column statistics of a spml/1 file");
  auto file = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  auto allow_nan = std::make_shared<bool>(false);
  cmd->add_option("FILE", *file, "dataset (HDF5, format spml/1)")->required();
  cmd->add_flag("--json", *json, "print JSON instead of text");
  cmd->add_flag("--allow-nonfinite", *allow_nan, "accept NaN/Inf values instead of rejecting the file");
  cmd->callback([=] {
    Dataset ds = read_dataset(*file, ReadOptions{*allow_nan});   // names and attributes are checked to be UTF-8
    if (const std::string why = utf8_problem(*file); *json && !why.empty())
      throw DatasetError(*file + ": the file name is " + why + "; JSON output holds only UTF-8 (rename the file)");
    nlohmann::json j = describe(*file, ds);
    if (*json)
      std::cout << j.dump(2) << "\n";
    else
      print_text(j);
  });
}

}  // namespace spml::cli
