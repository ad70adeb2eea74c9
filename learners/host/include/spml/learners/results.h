// results.csv, the public table `spml bench` writes and `spml compare` reads: the schema is
// defined here once. Schema 2 (written):
//
//   scenario,split,output,output_index,unit,algo,rmsemean,rmsestd,rmsemin,rmsemax,nllhmean,nllhstd,nllhmin,nllhmax,fits,fitsec,warnings
//
// `output` is the dataset's Y column name (`tau:joint0`), `output_index` its position, `unit`
// the unit of RMSE (from the name's prefix and the model's joint type, see column_unit; empty when unknown). Schema 1
// (no `output_index` column; `output` the index) is still read: its rows get no name or unit.
// One row per (scenario, test split, output, learner); statistics over the repetitions (std
// with ddof = 0); NLLH "inf" for learners without a variance; `fits` how many fits were made
// (1 for a deterministic learner), `fitsec` the mean fit time, `warnings` the learners'
// notes (commas turned into ';'). The paper's own tables (data/published) use the same
// statistic columns, with "-" for values the paper does not give.
#pragma once

#include <string>
#include <vector>

#include "spml/column_unit.h"   // the unit column

namespace spml {

struct ResultRow {
  std::string scenario, split, algo;
  int output = 0;
  double rmse_mean = 0, rmse_std = 0, rmse_min = 0, rmse_max = 0;
  double nllh_mean = 0, nllh_std = 0, nllh_min = 0, nllh_max = 0;
  int fits = 0;
  double fit_seconds = 0;
  std::string warnings;
  std::string output_name, unit;   // schema 2; empty when read from schema 1
};

// The header line, without the newline.
std::string results_header();
// One row as a CSV line, without the newline.
std::string results_line(const ResultRow& row);
// Reads a results.csv; throws naming the file, line and column.
std::vector<ResultRow> read_results(const std::string& path);
// Reads one of the paper's tables (algo,rmsemean,...; "-" = not given, "inf").
std::vector<ResultRow> read_published_table(const std::string& path);

// "tau:joint0 [N·m]", "y", or "output 2" for a schema-1 row.
std::string output_label(const ResultRow& row);

// Paper spellings that differ from ours ("SPGP-from-zeroes").
std::string canonical_algo(const std::string& name);

}  // namespace spml
