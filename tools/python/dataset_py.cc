// spml/1 datasets as Python dicts of NumPy arrays, through the C++ library (envs/dataset):
// the format is read, validated and written (atomically) there and nowhere else.
#include <pybind11/stl.h>

#include "convert.h"
#include "dataset_py.h"

namespace spml::py {
namespace {

pb::object optional_vector(const Eigen::VectorXd& v) { return v.size() ? pb::object(to_numpy(v)) : pb::none(); }

pb::dict split_dict(const Split& s) {
  pb::dict d;
  d["X"] = to_numpy(s.X);
  d["Y"] = to_numpy(s.Y);
  d["t"] = optional_vector(s.t);
  d["x_columns"] = s.x_columns;
  d["y_columns"] = s.y_columns;
  return d;
}

pb::object model_dict(const ModelInfo& m) {
  if (m.empty() && m.prior.size() == 0 && m.truth.size() == 0) return pb::none();
  pb::dict d;
  d["name"] = m.name;
  d["param_names"] = m.param_names;
  d["prior"] = optional_vector(m.prior);
  d["truth"] = optional_vector(m.truth);
  d["mjcf_path"] = m.mjcf_path;
  d["mjcf_xml"] = m.mjcf_xml;
  return d;
}

// d[key] as a string list, naming `where` when it is not one.
std::vector<std::string> names(const pb::dict& d, const char* key, const std::string& where) {
  if (!d.contains(key)) throw BadArgument(where + ": '" + key + "' is missing");
  try {
    return d[key].cast<std::vector<std::string>>();
  } catch (const pb::cast_error&) {
    throw BadArgument(where + ": '" + key + "' must be a list of strings");
  }
}

pb::dict as_dict(const pb::handle& obj, const std::string& where) {
  if (!pb::isinstance<pb::dict>(obj)) throw BadArgument(where + ": expected a dict, got " + std::string(pb::str(pb::type::of(obj))));
  return pb::reinterpret_borrow<pb::dict>(obj);
}

Split split_from(const std::string& name, const pb::handle& obj) {
  const std::string where = "split '" + name + "'";
  const pb::dict d = as_dict(obj, where);
  Split s;
  s.name = name;
  for (const char* key : {"X", "Y"})
    if (!d.contains(key)) throw BadArgument(where + ": '" + key + "' is missing");
  s.X = to_matrix(d["X"], where + ": X");
  s.Y = to_matrix(d["Y"], where + ": Y");
  s.x_columns = names(d, "x_columns", where);
  s.y_columns = names(d, "y_columns", where);
  if (d.contains("t") && !d["t"].is_none()) s.t = to_vector(d["t"], where + ": t");
  return s;
}

ModelInfo model_from(const pb::handle& obj) {
  ModelInfo m;
  if (obj.is_none()) return m;
  const pb::dict d = as_dict(obj, "model");
  auto text = [&](const char* key) { return d.contains(key) && !d[key].is_none() ? d[key].cast<std::string>() : std::string(); };
  m.name = text("name");
  m.mjcf_path = text("mjcf_path");
  m.mjcf_xml = text("mjcf_xml");
  if (d.contains("param_names") && !d["param_names"].is_none()) m.param_names = names(d, "param_names", "model");
  if (d.contains("prior") && !d["prior"].is_none()) m.prior = to_vector(d["prior"], "model: prior");
  if (d.contains("truth") && !d["truth"].is_none()) m.truth = to_vector(d["truth"], "model: truth");
  return m;
}

}  // namespace

pb::dict dataset_dict(const Dataset& ds) {
  pb::dict splits;
  for (const Split& s : ds.splits) splits[pb::str(s.name)] = split_dict(s);
  pb::dict out;
  out["splits"] = splits;
  out["model"] = model_dict(ds.model);
  out["provenance"] = ds.provenance;
  return out;
}

Dataset dataset_from(const pb::handle& splits, const pb::handle& model, const pb::handle& provenance) {
  Dataset ds;
  for (const auto& [name, split] : as_dict(splits, "splits")) ds.splits.push_back(split_from(pb::str(name), split));
  ds.model = model_from(model);
  if (!provenance.is_none())
    for (const auto& [key, value] : as_dict(provenance, "provenance")) ds.provenance[pb::str(key)] = pb::str(value);
  return ds;
}

Dataset dataset_arg(const pb::handle& data) {
  if (pb::isinstance<pb::dict>(data)) {
    const pb::dict d = pb::reinterpret_borrow<pb::dict>(data);
    if (!d.contains("splits")) throw BadArgument("data: a dict must be read_dataset()'s: 'splits' is missing");
    const pb::object none = pb::none();
    Dataset ds = dataset_from(d["splits"], d.contains("model") ? d["model"] : none, d.contains("provenance") ? d["provenance"] : none);
    validate(ds, "data (a dict)");
    return ds;
  }
  const std::string path = pb::str(data);
  return naming_missing_files({path}, [&] { return read_dataset(path); });
}

void bind_dataset(pb::module_& m) {
  m.def(
      "read_dataset",
      [](const std::string& path, bool allow_nonfinite) {
        const Dataset ds = naming_missing_files({path}, [&] { return read_dataset(path, ReadOptions{allow_nonfinite}); });
        return dataset_dict(ds);
      },
      pb::arg("path"), pb::arg("allow_nonfinite") = false);
  m.def(
      "write_dataset",
      [](const std::string& path, const pb::handle& splits, const pb::handle& model, const pb::handle& provenance) {
        write_dataset(path, dataset_from(splits, model, provenance));
      },
      pb::arg("path"), pb::arg("splits"), pb::arg("model") = pb::none(), pb::arg("provenance") = pb::none());
}

}  // namespace spml::py
