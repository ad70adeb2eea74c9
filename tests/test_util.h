// Helpers for tests: temporary folders and running the spml binary.
#pragma once

#include <sys/wait.h>

#include <Eigen/Core>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include <filesystem>
#include <map>
#include <random>
#include <stdexcept>
#include <sstream>
#include <string>

// Under the sanitizers (the asan preset: ASan + UBSan, several times slower) the longest
// end-to-end cases are skipped, and say so: each runs the code of the shorter ones on more
// data, and the main suite runs them all (README, "checking memory safety").
#ifdef SPML_SANITIZED
#define SPML_SKIP_UNDER_SANITIZERS() GTEST_SKIP() << "a long end-to-end case: run by the main suite, not under the sanitizers"
#else
#define SPML_SKIP_UNDER_SANITIZERS() static_cast<void>(0)
#endif

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

// Model texts for the hidden-effect tests (test_diagnose, test_realistic_draws).

inline std::string num(double v) {
  std::ostringstream s;
  s.precision(12);
  s << v;
  return s.str();
}

// A chain of n hinge bodies with random geometry, masses, axes and gravity direction.
inline std::string random_chain(std::mt19937_64& rng, int n, double payload) {
  std::uniform_real_distribution<double> u(-1, 1), pos(0.2, 0.5), mass(0.5, 3.0), inertia(0.005, 0.05);
  Eigen::Vector3d g(u(rng), u(rng), u(rng));
  g = 9.81 * g.normalized();
  std::ostringstream x;
  x << "<mujoco model=\"chain\">\n  <option gravity=\"" << g.x() << " " << g.y() << " " << g.z() << "\"/>\n  <worldbody>\n";
  for (int j = 0; j < n; ++j) {
    Eigen::Vector3d axis(u(rng), u(rng), u(rng));
    axis.normalize();
    double m = mass(rng);
    if (j == n - 1) m += payload;
    x << std::string(4 + 2 * j, ' ') << "<body name=\"b" << j << "\" pos=\"" << (j ? pos(rng) : 0.0) << " 0 0\">\n"
      << std::string(6 + 2 * j, ' ') << "<joint name=\"j" << j << "\" type=\"hinge\" axis=\"" << axis.x() << " " << axis.y() << " "
      << axis.z() << "\" armature=\"" << 0.05 << "\" damping=\"" << 0.5 << "\"/>\n"
      << std::string(6 + 2 * j, ' ') << "<inertial pos=\"" << 0.5 * pos(rng) << " " << 0.05 * u(rng) << " 0\" mass=\"" << m
      << "\" diaginertia=\"" << [&] {
           // Three moments within 30 % of each other always satisfy the triangle inequality.
           const double i0 = inertia(rng);
           std::uniform_real_distribution<double> f(0.7, 1.0);
           return num(i0 * f(rng)) + " " + num(i0 * f(rng)) + " " + num(i0 * f(rng));
         }() << "\"/>\n";
  }
  for (int j = n - 1; j >= 0; --j) x << std::string(4 + 2 * j, ' ') << "</body>\n";
  x << "  </worldbody>\n</mujoco>\n";
  return x.str();
}

// The model with one <custom> declaration per plugin text ("type=... joints=...").
inline std::string with_declarations(std::string xml, const std::vector<std::string>& texts) {
  if (texts.empty()) return xml;
  std::string custom = "  <custom>\n";
  for (size_t i = 0; i < texts.size(); ++i) custom += "    <text name=\"spml.plugin.hidden" + std::to_string(i) + "\" data=\"" + texts[i] + "\"/>\n";
  custom += "  </custom>\n";
  const auto end = xml.rfind("</mujoco>");
  return xml.insert(end, custom);
}

// One hidden effect of the plugin vocabulary on `joint`, its size 8-14 times `sigma`; the
// linear parameters the data should give back go into truth["effect@joint.param"]. A ripple's
// wavenumber is drawn from min_gear .. min_gear + 30.
inline std::string effect_text(const std::string& effect, const std::string& joint, double sigma, std::mt19937_64& rng,
                               std::map<std::string, double>& truth, int min_gear = 3) {
  std::uniform_real_distribution<double> k(8, 14), u(0, 1);
  const double a = k(rng) * sigma;
  const std::string key = effect + "@" + joint;
  if (effect == "coulomb") {
    truth[key + ".fc"] = a;
    return "type=coulomb joints=" + joint + " fc=" + num(a);
  }
  if (effect == "offset") {
    const double c = u(rng) < 0.5 ? -a : a;
    truth[key + ".c"] = c;
    return "type=offset joints=" + joint + " c=" + num(c);
  }
  if (effect == "stribeck") return "type=stribeck joints=" + joint + " fc=" + num(0.5 * a) + " fs=" + num(1.5 * a) + " vs=" + num(0.1 + 0.2 * u(rng));
  if (effect == "friction_band") {
    // The trajectory spans about +-1 rad; a band of width 0.5-0.8 rad inside it.
    const double lo = -0.6 + 0.5 * u(rng), w = 0.5 + 0.3 * u(rng);
    return "type=friction_band joints=" + joint + " lower=" + num(lo) + " upper=" + num(lo + w) + " level=" + num(a);
  }
  if (effect == "ripple") {
    const int gear = min_gear + static_cast<int>(u(rng) * 30);
    return "type=ripple joints=" + joint + " gear=" + std::to_string(gear) + " harmonics=1 amplitudes=" + num(a) + " phases=" + num(6 * u(rng));
  }
  if (effect == "asymmetric_friction") {
    // Direction-dependent viscous friction on top of Coulomb (asymmetric Coulomb alone is
    // Coulomb plus an offset: the data cannot tell them apart).
    const double fv = a / 0.8;
    return "type=asymmetric_friction joints=" + joint + " fc_pos=" + num(a) + " fc_neg=" + num(a) + " fv_pos=" + num(fv) + " fv_neg=" + num(0.2 * fv);
  }
  if (effect == "viscous") {
    // On top of the joint's MJCF damping; joint speeds are of order 1 rad/s.
    truth[key + ".fv"] = a;
    return "type=viscous joints=" + joint + " fv=" + num(a);
  }
  throw std::logic_error("unknown effect " + effect);
}

}  // namespace spml::test
