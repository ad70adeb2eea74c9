// spml import: CSV (header row) or MATLAB .mat into spml/1.
#include <filesystem>
#include <iostream>

#include "commands.h"
#include "spml/import.h"

namespace spml::cli {

void add_import(CLI::App& app) {
  auto* cmd = app.add_subcommand("import", "Convert a CSV (header row = column names) or MATLAB .mat file into spml/1");
  struct Args {
    std::string input, out, format = "auto";
    ImportSpec spec;
    std::vector<std::string> splits;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("INPUT", a->input, "CSV or .mat file")->required();
  cmd->add_option("--out,-o", a->out, "output spml/1 file")->required();
  cmd->add_option("--x", a->spec.x, "input columns: NAME, NEW=NAME or NEW=NAME*FACTOR (FACTOR: number or .mat scalar)")
      ->required()->delimiter(',');
  cmd->add_option("--y", a->spec.y, "target columns, same syntax as --x")->required()->delimiter(',');
  cmd->add_option("--t", a->spec.t, "time column [s]");
  cmd->add_option("--split", a->splits, "NAME:BEGIN:END in rows or percent, e.g. train:0:64% test:64%: (default: all rows as 'train')");
  cmd->add_option("--format", a->format, "input format")->check(CLI::IsMember({"auto", "csv", "mat"}));
  cmd->callback([a] {
    namespace fs = std::filesystem;
    if (!fs::exists(a->input)) throw DatasetError(a->input + ": no such file");
    if (fs::exists(a->out) && fs::equivalent(a->input, a->out))
      throw DatasetError(a->out + ": is the input file; choose another --out (import never overwrites its input)");
    std::string fmt = a->format;
    if (fmt == "auto") fmt = std::filesystem::path(a->input).extension() == ".mat" ? "mat" : "csv";
    Table table = fmt == "mat" ? read_mat_table(a->input) : read_csv_table(a->input);
    for (const auto& s : a->splits) a->spec.splits.push_back(parse_split_range(s));
    Dataset ds = table_to_dataset(table, a->spec);
    write_dataset(a->out, ds);
    std::cout << "wrote " << a->out << ":";
    for (const auto& s : ds.splits) std::cout << " " << s.name << " [" << s.rows() << " rows]";
    std::cout << "\n";
  });
}

}  // namespace spml::cli
