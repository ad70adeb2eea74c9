#include "spml/dataset.h"
#include "spml/matrix_file.h"

#include <H5Cpp.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace spml {
namespace {

namespace fs = std::filesystem;

std::string quote(const std::string& s) { return "'" + s + "'"; }

// ---- string attributes (variable-length UTF-8 on write; both kinds on read) ----

void write_string_attr(H5::H5Object& obj, const std::string& name, const std::string& value) {
  H5::StrType type(H5::PredType::C_S1, H5T_VARIABLE);
  type.setCset(H5T_CSET_UTF8);
  H5::Attribute attr = obj.createAttribute(name, type, H5::DataSpace(H5S_SCALAR));
  const char* data = value.c_str();
  attr.write(type, &data);
}

std::string read_string_attr(const H5::Attribute& attr, const std::string& where) {
  H5::DataType type = attr.getDataType();
  if (type.getClass() != H5T_STRING)
    throw DatasetError(where + ": attribute " + quote(attr.getName()) + " must be a string");
  H5::StrType stype = attr.getStrType();
  std::string value;
  attr.read(stype, value);   // the C++ API handles fixed and variable length here
  while (!value.empty() && value.back() == '\0') value.pop_back();
  return value;
}

bool has_attr(const H5::H5Object& obj, const std::string& name) { return obj.attrExists(name); }

// ---- matrices ----

void write_matrix(H5::Group& group, const std::string& name, const RowMatrix& m,
                  const std::vector<std::string>& columns) {
  hsize_t dims[2] = {static_cast<hsize_t>(m.rows()), static_cast<hsize_t>(m.cols())};
  H5::DataSet ds = group.createDataSet(name, H5::PredType::IEEE_F64LE, H5::DataSpace(2, dims));
  if (m.size() > 0) ds.write(m.data(), H5::PredType::NATIVE_DOUBLE);
  write_string_attr(ds, "columns", join_list(columns));
}

void write_vector(H5::Group& group, const std::string& name, const Eigen::VectorXd& v) {
  hsize_t dims[1] = {static_cast<hsize_t>(v.size())};
  H5::DataSet ds = group.createDataSet(name, H5::PredType::IEEE_F64LE, H5::DataSpace(1, dims));
  if (v.size() > 0) ds.write(v.data(), H5::PredType::NATIVE_DOUBLE);
}

void require_numeric(const H5::DataSet& ds, const std::string& where) {
  H5T_class_t cls = ds.getTypeClass();
  if (cls != H5T_FLOAT && cls != H5T_INTEGER)
    throw DatasetError(where + ": must hold numbers (float64), found a non-numeric type");
}

RowMatrix read_matrix(const H5::Group& group, const std::string& name, const std::string& where,
                      std::vector<std::string>& columns) {
  if (!group.nameExists(name)) throw DatasetError(where + ": dataset " + quote(name) + " is missing");
  const std::string here = where + ": dataset " + quote(name);
  H5::DataSet ds = group.openDataSet(name);
  require_numeric(ds, here);
  H5::DataSpace space = ds.getSpace();
  int rank = space.getSimpleExtentNdims();
  if (rank != 2)
    throw DatasetError(here + ": must be 2-D [rows, columns], found rank " + std::to_string(rank));
  hsize_t dims[2];
  space.getSimpleExtentDims(dims);
  RowMatrix m(static_cast<Eigen::Index>(dims[0]), static_cast<Eigen::Index>(dims[1]));
  if (m.size() > 0) {
    try {
      ds.read(m.data(), H5::PredType::NATIVE_DOUBLE);
    } catch (const H5::Exception& e) {
      throw DatasetError(here + ": read failed (file truncated or corrupt?): " + e.getDetailMsg());
    }
  }
  if (!has_attr(ds, "columns"))
    throw DatasetError(here + ": attribute 'columns' is missing (comma-separated column names)");
  columns = split_list(read_string_attr(ds.openAttribute("columns"), here));
  if (static_cast<Eigen::Index>(columns.size()) != m.cols())
    throw DatasetError(here + ": attribute 'columns' names " + std::to_string(columns.size()) +
                       " columns but the dataset has " + std::to_string(m.cols()));
  return m;
}

Eigen::VectorXd read_vector(const H5::Group& group, const std::string& name, const std::string& where) {
  const std::string here = where + ": dataset " + quote(name);
  H5::DataSet ds = group.openDataSet(name);
  require_numeric(ds, here);
  H5::DataSpace space = ds.getSpace();
  if (space.getSimpleExtentNdims() != 1) throw DatasetError(here + ": must be 1-D");
  hsize_t n;
  space.getSimpleExtentDims(&n);
  Eigen::VectorXd v(static_cast<Eigen::Index>(n));
  try {
    if (n > 0) ds.read(v.data(), H5::PredType::NATIVE_DOUBLE);
  } catch (const H5::Exception& e) {
    throw DatasetError(here + ": read failed (file truncated or corrupt?): " + e.getDetailMsg());
  }
  return v;
}

// Names of the child groups of `loc` in creation order when the file tracks it, else by name.
std::vector<std::string> child_groups(hid_t loc) {
  unsigned flags = 0;
  hid_t gcpl = H5Gget_create_plist(loc);
  if (gcpl >= 0) {
    H5Pget_link_creation_order(gcpl, &flags);
    H5Pclose(gcpl);
  }
  H5_index_t index = (flags & H5P_CRT_ORDER_INDEXED) ? H5_INDEX_CRT_ORDER : H5_INDEX_NAME;
  std::vector<std::string> names;
  auto visit = [](hid_t group, const char* name, const H5L_info_t*, void* out) -> herr_t {
    H5O_info_t info;
    if (H5Oget_info_by_name(group, name, &info, H5P_DEFAULT) >= 0 && info.type == H5O_TYPE_GROUP)
      static_cast<std::vector<std::string>*>(out)->push_back(name);
    return 0;
  };
  hsize_t idx = 0;
  if (H5Literate(loc, index, H5_ITER_INC, &idx, visit, &names) < 0)
    throw DatasetError("cannot list the groups (file truncated or corrupt?)");
  return names;
}

void check_finite(const RowMatrix& m, const std::vector<std::string>& columns, const std::string& where) {
  std::vector<Eigen::Index> bad_rows;
  std::string first_column;
  for (Eigen::Index r = 0; r < m.rows(); ++r) {
    for (Eigen::Index c = 0; c < m.cols(); ++c) {
      if (!std::isfinite(m(r, c))) {
        if (bad_rows.empty()) first_column = c < static_cast<Eigen::Index>(columns.size()) ? columns[c] : "?";
        bad_rows.push_back(r);
        break;
      }
    }
  }
  if (bad_rows.empty()) return;
  std::ostringstream msg;
  msg << where << ": non-finite values (NaN/Inf) in " << bad_rows.size() << " row(s): ";
  for (size_t i = 0; i < bad_rows.size() && i < 10; ++i) msg << (i ? ", " : "") << bad_rows[i];
  if (bad_rows.size() > 10) msg << ", ...";
  msg << " (first in column " << quote(first_column) << ")";
  throw DatasetError(msg.str());
}

}  // namespace

// ---------------------------------------------------------------------------------------

std::vector<std::string> split_list(const std::string& text, char sep) {
  std::vector<std::string> out;
  if (text.empty()) return out;
  std::string item;
  std::istringstream in(text);
  while (std::getline(in, item, sep)) {
    auto b = item.find_first_not_of(" \t");
    auto e = item.find_last_not_of(" \t\r\n");
    out.push_back(b == std::string::npos ? "" : item.substr(b, e - b + 1));
  }
  if (!text.empty() && text.back() == sep) out.push_back("");
  return out;
}

std::string join_list(const std::vector<std::string>& items, char sep) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) {
    if (i) out += sep;
    out += items[i];
  }
  return out;
}

Split Split::slice(Eigen::Index begin, Eigen::Index end, const std::string& name_of_slice) const {
  Split s;
  s.name = name_of_slice;
  s.x_columns = x_columns;
  s.y_columns = y_columns;
  s.X = X.middleRows(begin, end - begin);
  s.Y = Y.middleRows(begin, end - begin);
  if (t.size()) s.t = t.segment(begin, end - begin);
  return s;
}

int Split::x_index(const std::string& column) const {
  for (size_t i = 0; i < x_columns.size(); ++i)
    if (x_columns[i] == column) return static_cast<int>(i);
  return -1;
}
int Split::y_index(const std::string& column) const {
  for (size_t i = 0; i < y_columns.size(); ++i)
    if (y_columns[i] == column) return static_cast<int>(i);
  return -1;
}

const Split* Dataset::find(const std::string& split) const {
  for (const auto& s : splits)
    if (s.name == split) return &s;
  return nullptr;
}

const Split& Dataset::get(const std::string& split) const {
  if (const Split* s = find(split)) return *s;
  std::string have;
  for (const auto& s : splits) have += (have.empty() ? "" : ", ") + s.name;
  throw DatasetError((source.empty() ? "" : source + ": ") + "no split " + quote(split) + " (the file has: " + have + ")");
}

namespace {
// Column names must be non-empty and unique: every consumer matches columns by name.
void check_column_names(const std::vector<std::string>& columns, const std::string& where) {
  for (size_t i = 0; i < columns.size(); ++i) {
    if (columns[i].empty()) throw DatasetError(where + ": column " + std::to_string(i) + " has an empty name");
    for (size_t j = 0; j < i; ++j)
      if (columns[j] == columns[i])
        throw DatasetError(where + ": column name " + quote(columns[i]) + " appears twice (columns " +
                           std::to_string(j) + " and " + std::to_string(i) + ")");
  }
}
}  // namespace

namespace {

// Names and attributes are UTF-8 (the format says so, and JSON outputs need it).
void check_utf8(const std::string& text, const std::string& where) {
  if (const std::string why = utf8_problem(text); !why.empty()) throw DatasetError(where + ": " + why);
}

void check_names_utf8(const Dataset& ds, const std::string& where) {
  for (const auto& [k, v] : ds.provenance) {
    check_utf8(k, where + ": a root attribute name");
    check_utf8(v, where + ": root attribute '" + k + "'");
  }
  for (const Split& s : ds.splits) {
    check_utf8(s.name, where + ": a split name");
    for (const auto& c : s.x_columns) check_utf8(c, where + ": group " + quote(s.name) + ": dataset 'X': attribute 'columns'");
    for (const auto& c : s.y_columns) check_utf8(c, where + ": group " + quote(s.name) + ": dataset 'Y': attribute 'columns'");
  }
  const ModelInfo& m = ds.model;
  for (const auto* text : {&m.name, &m.mjcf_path, &m.mjcf_xml}) check_utf8(*text, where + ": group 'model'");
  for (const auto& n : m.param_names) check_utf8(n, where + ": group 'model': attribute 'param_names'");
}

// Rows are in time order: every consumer that looks at time (hold-outs, rollouts, filters)
// takes the array order for it.
void check_time_order(const Split& s, const std::string& where) {
  for (Eigen::Index i = 1; i < s.t.size(); ++i)
    if (s.t[i] < s.t[i - 1]) {
      std::ostringstream msg;
      msg << where << ": dataset 't': rows are not in time order (row " << i << ": t = " << s.t[i] << " after t = "
          << s.t[i - 1] << "); sort the rows by time";
      throw DatasetError(msg.str());
    }
}

}  // namespace

std::string utf8_problem(const std::string& text) {
  const auto* b = reinterpret_cast<const unsigned char*>(text.data());
  const size_t n = text.size();
  for (size_t i = 0; i < n;) {
    const unsigned c = b[i];
    size_t len = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xE ? 3 : (c >> 3) == 0x1E ? 4 : 0;
    bool ok = len > 0 && i + len <= n && !(len == 2 && c < 0xC2) && !(len == 4 && c > 0xF4);
    for (size_t k = 1; ok && k < len; ++k) ok = (b[i + k] >> 6) == 0x2;
    if (ok && len == 3) {
      const unsigned c1 = b[i + 1];
      ok = !(c == 0xE0 && c1 < 0xA0) && !(c == 0xED && c1 >= 0xA0);   // overlong, surrogates
    }
    if (ok && len == 4) ok = !(c == 0xF0 && b[i + 1] < 0x90) && !(c == 0xF4 && b[i + 1] >= 0x90);
    if (!ok) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%02x", c);
      return "not valid UTF-8 (byte " + std::string(hex) + " at offset " + std::to_string(i) + " of '" +
             text.substr(0, std::min<size_t>(i, 40)) + "...')";
    }
    i += len;
  }
  return "";
}

void validate(const Dataset& ds, const std::string& where, const ReadOptions& options) {
  if (ds.splits.empty()) throw DatasetError(where + ": contains no split groups");
  check_names_utf8(ds, where);
  for (size_t i = 0; i < ds.splits.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (ds.splits[i].name == ds.splits[j].name)
        throw DatasetError(where + ": split " + quote(ds.splits[i].name) + " is given twice");
  for (const Split& s : ds.splits) {
    const std::string g = where + ": group " + quote(s.name);
    if (s.name.empty() || s.name == "model" || s.name.find_first_of("/.") != std::string::npos)
      throw DatasetError(g + ": not a valid split name (non-empty, not 'model', no '/' or '.')");
    check_column_names(s.x_columns, g + ": dataset 'X'");
    check_column_names(s.y_columns, g + ": dataset 'Y'");
    if (static_cast<Eigen::Index>(s.x_columns.size()) != s.X.cols())
      throw DatasetError(g + ": dataset 'X': attribute 'columns' names " + std::to_string(s.x_columns.size()) +
                         " columns but the dataset has " + std::to_string(s.X.cols()));
    if (static_cast<Eigen::Index>(s.y_columns.size()) != s.Y.cols())
      throw DatasetError(g + ": dataset 'Y': attribute 'columns' names " + std::to_string(s.y_columns.size()) +
                         " columns but the dataset has " + std::to_string(s.Y.cols()));
    if (s.X.rows() != s.Y.rows())
      throw DatasetError(g + ": X has " + std::to_string(s.X.rows()) + " rows but Y has " +
                         std::to_string(s.Y.rows()));
    if (s.X.rows() == 0) throw DatasetError(g + ": split is empty (0 rows)");
    if (s.X.cols() == 0) throw DatasetError(g + ": dataset 'X' has no columns");
    if (s.Y.cols() == 0) throw DatasetError(g + ": dataset 'Y' has no columns");
    if (s.t.size() != 0 && s.t.size() != s.X.rows())
      throw DatasetError(g + ": dataset 't' has " + std::to_string(s.t.size()) + " entries but X has " +
                         std::to_string(s.X.rows()) + " rows");
    if (!options.allow_nonfinite) {
      check_finite(s.X, s.x_columns, g + ": dataset 'X'");
      check_finite(s.Y, s.y_columns, g + ": dataset 'Y'");
      if (s.t.size()) check_finite(RowMatrix(s.t), {"t"}, g + ": dataset 't'");
    }
    check_time_order(s, g);
  }
  const ModelInfo& m = ds.model;
  const auto M = static_cast<Eigen::Index>(m.param_names.size());
  if ((m.prior.size() && m.prior.size() != M) || (m.truth.size() && m.truth.size() != M))
    throw DatasetError(where + ": group 'model': prior/truth length differs from the " +
                       std::to_string(M) + " parameter names");
}

Dataset read_dataset(const std::string& path, const ReadOptions& options) {
  quiet_hdf5();
  if (!fs::exists(path)) throw DatasetError(path + ": no such file");
  if (fs::is_directory(path)) throw DatasetError(path + ": is a directory, not a dataset file");
  htri_t is_hdf5 = H5Fis_hdf5(path.c_str());
  if (is_hdf5 <= 0) throw DatasetError(path + ": not an HDF5 file (or truncated / corrupt)");

  Dataset out;
  try {
    H5::H5File file;
    try {
      file.openFile(path, H5F_ACC_RDONLY);
    } catch (const H5::Exception&) {
      throw DatasetError(path + ": cannot be opened as HDF5 (truncated or corrupt?)");
    }
    H5::Group root = file.openGroup("/");
    if (!has_attr(root, "format"))
      throw DatasetError(path + ": root attribute 'format' is missing (expected \"" + kFormatName + "\")");
    std::string format = read_string_attr(root.openAttribute("format"), path);
    if (format != kFormatName) {
      if (format.rfind("spml/", 0) == 0)
        throw DatasetError(path + ": format version " + quote(format) + " is not supported (this reader knows " +
                           kFormatName + ")");
      throw DatasetError(path + ": root attribute 'format' is " + quote(format) + ", not \"" + kFormatName + "\"");
    }
    for (int i = 0; i < root.getNumAttrs(); ++i) {
      H5::Attribute a = root.openAttribute(static_cast<unsigned>(i));
      if (a.getName() == "format" || a.getTypeClass() != H5T_STRING) continue;
      out.provenance[a.getName()] = read_string_attr(a, path);
    }
    std::vector<std::string> groups;
    try {
      groups = child_groups(root.getId());
    } catch (const DatasetError& e) {
      throw DatasetError(path + ": " + e.what());
    }
    for (const std::string& name : groups) {
      H5::Group g = root.openGroup(name);
      const std::string where = path + ": group " + quote(name);
      if (name == "model") {
        ModelInfo& m = out.model;
        if (has_attr(g, "name")) m.name = read_string_attr(g.openAttribute("name"), where);
        if (has_attr(g, "param_names")) m.param_names = split_list(read_string_attr(g.openAttribute("param_names"), where));
        if (has_attr(g, "mjcf_path")) m.mjcf_path = read_string_attr(g.openAttribute("mjcf_path"), where);
        if (has_attr(g, "mjcf_xml")) m.mjcf_xml = read_string_attr(g.openAttribute("mjcf_xml"), where);
        if (g.nameExists("prior")) m.prior = read_vector(g, "prior", where);
        if (g.nameExists("truth")) m.truth = read_vector(g, "truth", where);
        continue;
      }
      Split s;
      s.name = name;
      s.X = read_matrix(g, "X", where, s.x_columns);
      s.Y = read_matrix(g, "Y", where, s.y_columns);
      if (g.nameExists("t")) s.t = read_vector(g, "t", where);
      out.splits.push_back(std::move(s));
    }
  } catch (const H5::Exception& e) {
    throw DatasetError(path + ": HDF5 error (truncated or corrupt file?): " + e.getFuncName() + ": " +
                       e.getDetailMsg());
  }
  validate(out, path, options);
  out.source = path;
  return out;
}

namespace {

// Where an output cannot go, named as the user gave it (not as the temporary file).
void check_output_path(const std::string& path) {
  fs::path target(path);
  if (fs::is_directory(target)) throw DatasetError(path + ": is a directory; give a file name to write");
  if (target.has_parent_path() && !fs::exists(target.parent_path()))
    throw DatasetError(path + ": directory " + target.parent_path().string() + " does not exist");
}

// Writes `bytes` to `tmp` and renames it to `path`; a failed write (disk full) removes `tmp`.
void write_bytes_atomic(const std::string& path, const std::string& tmp, const char* bytes, size_t size) {
  std::error_code ec;
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (f) f.write(bytes, static_cast<std::streamsize>(size));
    f.close();
    if (!f) {
      const int err = errno;
      fs::remove(tmp, ec);
      throw DatasetError(path + ": write failed (" + std::string(err ? std::strerror(err) : "disk full or no permission?") + ")");
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code rm;
    fs::remove(tmp, rm);
    throw DatasetError(path + ": cannot move the finished file into place: " + ec.message());
  }
}

// Creates `path` atomically: `body` fills an HDF5 file held in memory (the core driver, no
// backing store), whose image is then written to a temporary file and renamed into place.
// HDF5 itself never meets a full disk: when it did, its close failed, the file stayed
// registered, and closing it again at exit crashed the process inside the library.
template <class Body>
void write_h5_atomic(const std::string& path, Body body) {
  quiet_hdf5();
  check_output_path(path);
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  // Track creation order so groups read back in the order they were written.
  const hid_t fcpl = H5Pcreate(H5P_FILE_CREATE), fapl = H5Pcreate(H5P_FILE_ACCESS);
  H5Pset_link_creation_order(fcpl, H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
  H5Pset_fapl_core(fapl, 1 << 20, 0);
  const hid_t fid = H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, fcpl, fapl);
  H5Pclose(fcpl);
  H5Pclose(fapl);
  if (fid < 0) throw DatasetError(path + ": HDF5 cannot create a file in memory");
  std::vector<char> image;
  try {
    {
      H5::H5File file(fid);   // a reference of its own: its destructor leaves fid open
      body(file);
    }
    H5Fflush(fid, H5F_SCOPE_GLOBAL);
    const ssize_t size = H5Fget_file_image(fid, nullptr, 0);
    if (size < 0) throw DatasetError(path + ": HDF5 cannot produce the file's image");
    image.resize(static_cast<size_t>(size));
    if (H5Fget_file_image(fid, image.data(), image.size()) != size) throw DatasetError(path + ": HDF5 cannot produce the file's image");
  } catch (const H5::Exception& e) {
    H5Fclose(fid);
    throw DatasetError(path + ": write failed: " + e.getDetailMsg());
  } catch (...) {
    H5Fclose(fid);
    throw;
  }
  H5Fclose(fid);
  write_bytes_atomic(path, tmp, image.data(), image.size());
}

// Opens (creating as needed) the group holding "a/b/name" and returns it.
H5::Group parent_group(H5::H5File& file, const std::string& path, std::string* leaf) {
  H5::Group g = file.openGroup("/");
  size_t start = 0, slash;
  while ((slash = path.find('/', start)) != std::string::npos) {
    const std::string part = path.substr(start, slash - start);
    g = g.nameExists(part) ? g.openGroup(part) : g.createGroup(part);
    start = slash + 1;
  }
  *leaf = path.substr(start);
  return g;
}

void collect_matrices(const H5::Group& g, const std::string& prefix, const std::string& where, MatrixFile& out) {
  for (hsize_t i = 0; i < g.getNumObjs(); ++i) {
    const std::string name = g.getObjnameByIdx(i);
    const std::string full = prefix.empty() ? name : prefix + "/" + name;
    if (g.getObjTypeByIdx(i) == H5G_GROUP) {
      collect_matrices(g.openGroup(name), full, where, out);
    } else {
      std::vector<std::string> columns;
      out.matrices[full] = read_matrix(g, name, where, columns);
    }
  }
}

}  // namespace

void write_dataset(const std::string& path, const Dataset& ds) {
  validate(ds, path, ReadOptions{});
  write_h5_atomic(path, [&](H5::H5File& file) {
    H5::Group root = file.openGroup("/");
    write_string_attr(root, "format", kFormatName);
    for (const auto& [key, value] : ds.provenance)
      if (key != "format") write_string_attr(root, key, value);
    for (const Split& s : ds.splits) {
      H5::Group g = file.createGroup("/" + s.name);
      write_matrix(g, "X", s.X, s.x_columns);
      write_matrix(g, "Y", s.Y, s.y_columns);
      if (s.t.size()) write_vector(g, "t", s.t);
    }
    if (!ds.model.empty()) {
      const ModelInfo& m = ds.model;
      H5::Group g = file.createGroup("/model");
      write_string_attr(g, "name", m.name);
      write_string_attr(g, "param_names", join_list(m.param_names));
      if (!m.mjcf_path.empty()) write_string_attr(g, "mjcf_path", m.mjcf_path);
      if (!m.mjcf_xml.empty()) write_string_attr(g, "mjcf_xml", m.mjcf_xml);
      if (m.prior.size()) write_vector(g, "prior", m.prior);
      if (m.truth.size()) write_vector(g, "truth", m.truth);
    }
  });
}

void write_matrix_file(const std::string& path, const MatrixFile& mf) {
  write_h5_atomic(path, [&](H5::H5File& file) {
    H5::Group root = file.openGroup("/");
    for (const auto& [key, value] : mf.attributes) write_string_attr(root, key, value);
    for (const auto& [name, m] : mf.matrices) {
      std::string leaf;
      H5::Group g = parent_group(file, name, &leaf);
      std::vector<std::string> columns;
      for (Eigen::Index j = 0; j < m.cols(); ++j) columns.push_back(std::to_string(j));
      write_matrix(g, leaf, m, columns);
    }
  });
}

MatrixFile read_matrix_file(const std::string& path) {
  quiet_hdf5();
  MatrixFile out;
  try {
    H5::H5File file(path, H5F_ACC_RDONLY);
    H5::Group root = file.openGroup("/");
    for (int i = 0; i < root.getNumAttrs(); ++i) {
      H5::Attribute a = root.openAttribute(static_cast<unsigned>(i));
      out.attributes[a.getName()] = read_string_attr(a, path);
    }
    collect_matrices(root, "", path, out);
  } catch (const H5::Exception& e) {
    throw DatasetError(path + ": cannot read: " + e.getDetailMsg());
  }
  return out;
}

void write_text_atomic(const std::string& path, const std::string& content) {
  check_output_path(path);
  write_bytes_atomic(path, path + ".tmp-" + std::to_string(::getpid()), content.data(), content.size());
}

void quiet_hdf5() {
  // HDF5 prints its whole error stack (dozens of HDF5-DIAG lines) before spml's own message;
  // every HDF5 failure is reported by spml instead.
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}

}  // namespace spml
