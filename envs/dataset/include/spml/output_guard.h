// A command must never write over one of its own inputs. Both checks compare files by
// filesystem identity (a link, "./x" or "../d/x" is the same file), not by spelling, and
// return the problem as text ("" when none) so that each command throws its own error type.
#pragma once

#include <string>
#include <vector>

namespace spml {

// `out` (an output file, existing or not) against every input file: the problem names both
// paths when `out` is one of them. Inputs that do not exist are skipped (their own reader
// reports them).
std::string output_is_input(const std::string& out, const std::vector<std::string>& inputs);

// Inputs against what a command writes into the folder `out_dir`: the files `files` (names in
// out_dir) and everything below the folders `folders` (names in out_dir). The problem names
// the first input that would be overwritten.
std::string input_among_outputs(const std::vector<std::string>& inputs, const std::string& out_dir,
                                const std::vector<std::string>& files, const std::vector<std::string>& folders);

}  // namespace spml
