// spml import: CSV (header row) or MATLAB .mat into spml/1.
#include <filesystem>
#include <iostream>

#include "commands.h"
#include "spml/import.h"
#include "spml/output_guard.h"
#include "spml/parse.h"

namespace spml::cli {

void add_import(CLI::App& app) {
  auto* cmd = app.add_subcommand("import", "Convert a CSV (header row = column names) or MATLAB .mat file into spml/1");
  struct Args {
    std::string input, out, format = "auto";
    ImportSpec spec;
    std::vector<std::string> splits, text;
    std::string lowpass = "0", order = "4", drop = "0", decimate = "1";
    std::string delimiter = ",";
    CsvDialect dialect;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("INPUT", a->input, "CSV or .mat file (or none, with --text)");
  cmd->add_option("--text", a->text, "a text log FILE=NAMES holding len(NAMES) values per sample, e.g. "
                                     "pos.txt=q:joint{1..7} (repeatable; replaces INPUT)");
  cmd->add_option("--lowpass", a->lowpass, "zero-phase Butterworth low-pass cut-off [Hz] on every column (0: none)")
      ->check(finite_number(0.0, 1e12));
  cmd->add_option("--filter-order", a->order, "Butterworth order (even)")->capture_default_str();
  cmd->add_flag("--derive", a->spec.conditioning.derive, "add qd:/qdd:<joint> by central differences of q:<joint>");
  cmd->add_option("--drop-edges", a->drop, "samples dropped at each end after filtering/differentiation");
  cmd->add_option("--decimate", a->decimate, "keep every K-th sample, after a zero-phase anti-alias low-pass (order 8 at 0.8 of the "
                                             "new Nyquist frequency) on every column");
  cmd->add_flag("--no-anti-alias", [a](std::int64_t) { a->spec.conditioning.anti_alias = false; },
                "--decimate keeps every K-th sample without the anti-alias low-pass (raw differences' noise folds into the band)");
  cmd->add_option("--out,-o", a->out, "output spml/1 file")->required();
  cmd->add_option("--x", a->spec.x, "input columns: NAME, NEW=NAME or NEW=NAME*FACTOR (FACTOR: number or .mat scalar)")
      ->required()->delimiter(',');
  cmd->add_option("--y", a->spec.y, "target columns, same syntax as --x")->required()->delimiter(',');
  cmd->add_option("--t", a->spec.t, "time column [s]");
  cmd->add_option("--split", a->splits, "NAME:BEGIN:END in rows or percent, e.g. train:0:64% test:64%: (default: all rows as 'train')");
  cmd->add_option("--format", a->format, "input format")->check(CLI::IsMember({"auto", "csv", "mat"}));
  cmd->add_option("--delimiter", a->delimiter, "CSV cell delimiter: one character, or 'tab' (default ',')");
  auto* comment = cmd->add_option("--comment", a->dialect.comment, "CSV lines starting with this text are skipped (e.g. '#'; default: none)");
  cmd->callback([a, comment] {
    namespace fs = std::filesystem;
    std::vector<std::string> inputs;
    if (!a->input.empty()) inputs.push_back(a->input);
    for (const auto& t : a->text) inputs.push_back(t.substr(0, t.find('=')));
    if (a->input.empty() == a->text.empty()) throw CLI::ValidationError("INPUT", "give either INPUT or --text logs");
    for (const auto& in : inputs)
      if (!fs::exists(in)) throw DatasetError(in + ": no such file");
    if (const std::string p = output_is_input(a->out, inputs); !p.empty()) throw CLI::ValidationError("--out", p);
    Conditioning& c = a->spec.conditioning;
    const double lowpass = finite_option("--lowpass", a->lowpass, 0.0, 1e12);
    const auto order = parse_integer(a->order, 2, 12), drop = parse_integer(a->drop, 0, 1000000000),
               decimate = parse_integer(a->decimate, 1, 1000000);
    if (!order || *order % 2) throw CLI::ValidationError("--filter-order", "'" + a->order + "' is not an even number in [2, 12]");
    if (!drop) throw CLI::ValidationError("--drop-edges", "'" + a->drop + "' is not a whole number >= 0");
    if (!decimate) throw CLI::ValidationError("--decimate", "'" + a->decimate + "' is not a whole number >= 1");
    if (!a->spec.conditioning.anti_alias && *decimate <= 1)
      throw CLI::ValidationError("--no-anti-alias", "applies to --decimate K with K >= 2 (there is no decimation to leave unfiltered)");
    c.lowpass_hz = lowpass;
    c.filter_order = static_cast<int>(*order);
    c.drop_edges = static_cast<int>(*drop);
    c.decimate = static_cast<int>(*decimate);
    std::string fmt = a->format;
    if (fmt == "auto") fmt = std::filesystem::path(a->input).extension() == ".mat" ? "mat" : "csv";
    const std::string d = a->delimiter == "tab" || a->delimiter == "\\t" ? "\t" : a->delimiter;
    if (d.size() != 1 || d[0] == '"' || d[0] == ' ' || d[0] == '\n' || d[0] == '\r')
      throw CLI::ValidationError("--delimiter", "'" + a->delimiter + "' is not one character other than a quote, space or newline (or 'tab')");
    if (a->dialect.comment.find_first_of(" \t\n\r") != std::string::npos)
      throw CLI::ValidationError("--comment", "'" + a->dialect.comment + "' holds a blank or newline");
    if (comment->count() && a->dialect.comment.empty())
      throw CLI::ValidationError("--comment", "is empty: every line would be a comment (leave --comment out to skip none)");
    if (a->dialect.comment.find(d) != std::string::npos)
      throw CLI::ValidationError("--comment", "'" + a->dialect.comment + "' holds the cell delimiter '" + a->delimiter + "'");
    a->dialect.delimiter = d[0];
    if ((a->delimiter != "," || !a->dialect.comment.empty()) && (fmt != "csv" || !a->text.empty()))
      throw CLI::ValidationError("--delimiter", "--delimiter and --comment apply to CSV input only");
    Table table = !a->text.empty() ? read_text_logs(a->text) : fmt == "mat" ? read_mat_table(a->input) : read_csv_table(a->input, a->dialect);
    for (const auto& s : a->splits) a->spec.splits.push_back(parse_split_range(s));
    a->spec.x = expand_names(join_list(a->spec.x));   // q:joint{1..7} -> q:joint1, ..., q:joint7
    a->spec.y = expand_names(join_list(a->spec.y));
    Dataset ds = table_to_dataset(table, a->spec);
    write_dataset(a->out, ds);
    std::cout << "wrote " << a->out << ":";
    for (const auto& s : ds.splits) std::cout << " " << s.name << " [" << s.rows() << " rows]";
    std::cout << "\n";
  });
}

}  // namespace spml::cli
