// Plain HDF5 files of named matrices, for results that are not datasets (bench units,
// predictions.h5), and atomic writes of text files. Writes go to a temporary file that is
// renamed into place, so a reader never sees half a file.
#pragma once

#include <map>
#include <string>

#include "spml/dataset.h"

namespace spml {

struct MatrixFile {
  std::map<std::string, RowMatrix> matrices;           // "group/sub/name" -> matrix
  std::map<std::string, std::string> attributes;       // root string attributes
};

void write_matrix_file(const std::string& path, const MatrixFile& file);
MatrixFile read_matrix_file(const std::string& path);   // throws DatasetError naming the file

// Refuses a path that is a folder, or whose folder is missing, naming the path (never the
// temporary file); a failed write (disk full) removes the temporary file.
void write_text_atomic(const std::string& path, const std::string& content);

// Turns off HDF5's automatic printing of its error stack (every failure is reported by spml
// with the file named). Called by every reader and writer here; also for libraries that use
// HDF5 on their own (matio for .mat v7.3).
void quiet_hdf5();

}  // namespace spml
