// Helpers for tests: temporary folders and running the spml binary.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include <filesystem>
#include <string>

namespace spml::test {

// A fresh folder for this test process (its pid in the name), removed when the process
// ends; set SPML_KEEP_TEST_FILES=1 to keep it for a look.
inline std::filesystem::path temp_dir(const std::string& name) {
  struct Cleanup {
    std::vector<std::filesystem::path> dirs;
    ~Cleanup() {
      if (std::getenv("SPML_KEEP_TEST_FILES")) return;
      std::error_code ec;
      for (const auto& d : dirs) std::filesystem::remove_all(d, ec);
    }
  };
  static Cleanup cleanup;
  auto dir = std::filesystem::temp_directory_path() / ("spml-test-" + name + "-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  cleanup.dirs.push_back(dir);
  return dir;
}

struct RunResult {
  int exit_code;
  std::string output;   // stdout and stderr together
};

// Runs a shell command, capturing output and exit status.
inline RunResult run(const std::string& cmd) {
  RunResult r{-1, ""};
  FILE* pipe = popen((cmd + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

inline std::string spml_bin() { return SPML_BIN; }

}  // namespace spml::test
