// Prints MuJoCo steps per second for the SimDyn arm without and with its force plugins
// (friction band + ripple through the mjcb_passive dispatcher). A benchmark, not a test.
#include <chrono>
#include <cstdio>

#include "spml/envs/mujoco_model.h"
#include "spml/force_effects.h"

using namespace spml;

static double steps_per_second(const std::string& file, bool plugins) {
  ModelPtr m = load_mjcf(mjcf_path(file));
  DataPtr d = make_data(m.get());
  ForceEffects fx(m.get(), file);
  if (plugins) fx.attach();
  const int steps = 200000;
  auto t0 = std::chrono::steady_clock::now();
  for (int k = 0; k < steps; ++k) {
    for (int i = 0; i < m->nv; ++i) d->qfrc_applied[i] = 50 * std::sin(1e-3 * k + i);
    step(m.get(), d.get(), fx);
  }
  return steps / std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

int main() {
  double plain = steps_per_second("planar_arm3.xml", false);
  double with = steps_per_second("planar_arm3_gl.xml", true);
  std::printf("planar_arm3 steps/s without plugins: %.0f\n", plain);
  std::printf("planar_arm3 steps/s with band+ripple plugins: %.0f (%.1f %% of plain)\n", with, 100 * with / plain);
  return 0;
}
