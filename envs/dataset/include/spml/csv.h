// The one CSV reader of spml: a header row of names, then rows of text cells. Used by
// `spml import` (cells then parsed as numbers) and by the results readers (bench, compare).
#pragma once

#include <string>
#include <vector>

namespace spml {

struct CsvText {
  std::string source;                          // file name, for messages
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;  // each as wide as the header
  std::vector<size_t> line;                    // 1-based line number of each row
  int column(const std::string& name) const;   // index or -1
};

// How cells are separated, and which lines are comments.
struct CsvDialect {
  char delimiter = ',';    // ',' ';' '\t' '|' ... (a quote, a newline or a space is refused)
  std::string comment;     // a line whose first non-blank text starts with this is skipped ("": none)
};

// Throws DatasetError naming the file and line: not a text file (NUL bytes, an HDF5 or
// other binary file), no header, an empty or repeated header name, a row of another width.
// Blank lines and comment lines are skipped; cells are trimmed of surrounding spaces (and
// tabs, unless the tab is the delimiter); a cell in double quotes may hold the delimiter (""
// is one quote, RFC 4180); a UTF-8 byte order mark before the header is dropped.
CsvText read_csv(const std::string& path, const CsvDialect& dialect = {});

}  // namespace spml
