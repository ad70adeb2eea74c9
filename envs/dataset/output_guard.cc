#include "spml/output_guard.h"

#include <filesystem>

namespace spml {
namespace fs = std::filesystem;

namespace {

bool same_file(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  return fs::exists(a, ec) && fs::exists(b, ec) && fs::equivalent(a, b, ec) && !ec;
}

// `p` lies below the folder `dir` (both resolved through links; the folder need not exist).
bool inside(const fs::path& p, const fs::path& dir) {
  std::error_code ec;
  const fs::path rel = fs::weakly_canonical(p, ec).lexically_relative(fs::weakly_canonical(dir, ec));
  return !rel.empty() && rel != "." && *rel.begin() != "..";
}

}  // namespace

std::string output_is_input(const std::string& out, const std::vector<std::string>& inputs) {
  for (const auto& in : inputs)
    if (!in.empty() && same_file(in, out))
      return out + ": is the input file " + in + "; choose another --out (spml never overwrites its inputs)";
  return "";
}

std::string input_among_outputs(const std::vector<std::string>& inputs, const std::string& out_dir,
                                const std::vector<std::string>& files, const std::vector<std::string>& folders) {
  for (const auto& in : inputs) {
    if (in.empty()) continue;
    bool hit = false;
    for (const auto& f : files) {
      const fs::path target = fs::path(out_dir) / f;
      std::error_code ec;
      hit |= same_file(in, target) || fs::weakly_canonical(in, ec) == fs::weakly_canonical(target, ec);
    }
    for (const auto& d : folders) hit |= inside(in, fs::path(out_dir) / d);
    if (hit)
      return in + ": is one of the files written into --out " + out_dir +
             ": it would be overwritten; copy it elsewhere or choose another --out";
  }
  return "";
}

}  // namespace spml
