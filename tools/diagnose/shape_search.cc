// Stage 4b, shape search: variable projection over a candidate's shape. For each shape the
// amplitudes are the least-squares ones, so only the drop of the residual sum of squares is
// searched - on a grid over the plugin's own ranges, then refined locally (continuous
// parameters only).
#include <nlopt.hpp>

#include <algorithm>
#include <cmath>
#include <functional>

#include "diagnosis.h"
#include "parallel.h"

namespace spml::diagnose_detail {
namespace {

// The drop of the residual sum of squares at one shape (a rank-0 gain when the plugin refuses
// the shape), and the best shape found so far.
struct ShapeSearch {
  std::function<Gain(const std::vector<double>&, BlockColumns*)> evaluate;
  const Candidate& c;
  int per_axis = 0;
  std::vector<double> best;
  double best_drop = -1;

  // Keeps p when it gains more than the best so far (or at least `tolerance` of it); `take`
  // with its gain already evaluated.
  bool offer(const std::vector<double>& p, double tolerance = 0) { return take(p, evaluate(p, nullptr), tolerance); }
  bool take(const std::vector<double>& p, const Gain& g, double tolerance = 0) {
    const bool better = g.rank > 0 && (tolerance > 0 ? g.rss_drop >= best_drop * (1 - tolerance) : g.rss_drop > best_drop);
    if (!better) return false;
    best = p;
    best_drop = tolerance > 0 ? std::max(best_drop, g.rss_drop) : g.rss_drop;
    return true;
  }
  double width(size_t k) const { return c.shape_range[k].second - c.shape_range[k].first; }
};

// Grid: every whole number of a small integer range, else points per axis so that the
// whole grid stays a few hundred shapes.
std::vector<std::vector<double>> grid_axes(const Candidate& c, int per_axis) {
  const size_t ns = c.shape.size();
  std::vector<std::vector<double>> axes(ns);
  for (size_t k = 0; k < ns; ++k) {
    auto [lo, hi] = c.shape_range[k];
    const auto* sp = c.shape[k];
    if (sp->integer && std::ceil(lo) <= std::floor(hi) && std::floor(hi) - std::ceil(lo) < 250) {
      for (double v = std::ceil(lo); v <= std::floor(hi); v += 1) axes[k].push_back(v);
      continue;
    }
    for (int i = 0; i < per_axis; ++i) {
      const double f = per_axis == 1 ? 0.5 : static_cast<double>(i) / (per_axis - 1);
      double v = sp->log_scale ? lo * std::pow(hi / lo, f) : lo + f * (hi - lo);
      if (sp->integer) v = std::round(v);
      if (axes[k].empty() || axes[k].back() != v) axes[k].push_back(v);
    }
  }
  return axes;
}

// The grid's points evaluated on the cores (`serial`: on one thread), offered in grid order.
void grid_scan(ShapeSearch& s, const std::vector<std::vector<double>>& axes, bool serial) {
  const size_t ns = axes.size();
  std::vector<std::vector<double>> points;
  std::vector<size_t> idx(ns, 0);
  s.best.assign(ns, 0.0);
  for (;;) {
    std::vector<double> point(ns);
    for (size_t k = 0; k < ns; ++k) point[k] = axes[k][idx[k]];
    points.push_back(std::move(point));
    size_t k = 0;
    while (k < ns && ++idx[k] == axes[k].size()) idx[k++] = 0;
    if (k == ns) break;
  }
  std::vector<Gain> gains(points.size());
  parallel_for(points.size(), [&](size_t i) { gains[i] = s.evaluate(points[i], nullptr); }, serial);
  for (size_t i = 0; i < points.size(); ++i) s.take(points[i], gains[i]);
}

// Zoomed scans per parameter around the best grid point: the objective is piecewise constant
// in parameters that select samples (band edges), which derivative-free simplex methods stall on.
void zoom(ShapeSearch& s, const std::vector<size_t>& cont) {
  for (int round = 0; round < 3 && !cont.empty(); ++round)
    for (size_t k : cont) {
      const double cell = s.width(k) / (s.per_axis - 1) / std::pow(4.0, round);
      for (int i = -8; i <= 8; ++i) {
        std::vector<double> p = s.best;
        p[k] = std::clamp(s.best[k] + cell * i / 8.0, s.c.shape_range[k].first, s.c.shape_range[k].second);
        if (p[k] == s.best[k]) continue;
        s.offer(p);
      }
    }
}

// Parameters that select samples leave a plateau of equally good values between two samples;
// take its middle, the value least likely to misplace unseen samples.
void plateau_middle(ShapeSearch& s, const std::vector<size_t>& cont) {
  for (size_t k : cont) {
    const double fine = s.width(k) / (s.per_axis - 1) / 256;
    double ends[2] = {s.best[k], s.best[k]};
    for (int side = 0; side < 2; ++side)
      for (int i = 1; i <= 24; ++i) {
        std::vector<double> p = s.best;
        p[k] = s.best[k] + (side ? fine : -fine) * i;
        if (p[k] < s.c.shape_range[k].first || p[k] > s.c.shape_range[k].second) break;
        const Gain g = s.evaluate(p, nullptr);
        if (!(g.rank > 0 && g.rss_drop >= s.best_drop * (1 - 1e-12))) break;
        ends[side] = p[k];
      }
    if (ends[0] != ends[1]) {
      std::vector<double> p = s.best;
      p[k] = 0.5 * (ends[0] + ends[1]);
      s.offer(p, 1e-12);
    }
  }
}

// A subplex polish (NLopt) for the smooth parameters (a Stribeck velocity), within a
// sixteenth of a grid cell.
void polish(ShapeSearch& s, const std::vector<size_t>& cont) {
  if (cont.empty()) return;
  std::vector<double> lb, ub, x;
  for (size_t k : cont) {
    const double cell = s.width(k) / (s.per_axis - 1) / 16;
    lb.push_back(std::max(s.c.shape_range[k].first, s.best[k] - cell));
    ub.push_back(std::min(s.c.shape_range[k].second, s.best[k] + cell));
    x.push_back(s.best[k]);
  }
  const std::vector<double> start = s.best;
  struct Ctx {
    std::function<double(const std::vector<double>&)> f;
  } ctx{[&](const std::vector<double>& v) {
    std::vector<double> p = start;
    for (size_t a = 0; a < cont.size(); ++a) p[cont[a]] = v[a];
    const Gain g = s.evaluate(p, nullptr);
    return g.rank > 0 ? g.rss_drop : 0.0;
  }};
  nlopt::opt local(nlopt::LN_SBPLX, static_cast<unsigned>(cont.size()));
  local.set_lower_bounds(lb);
  local.set_upper_bounds(ub);
  local.set_max_objective([](const std::vector<double>& v, std::vector<double>&, void* data) { return static_cast<Ctx*>(data)->f(v); }, &ctx);
  local.set_maxeval(static_cast<int>(25 * cont.size()));
  local.set_xtol_rel(1e-4);
  double value = s.best_drop;
  try {
    local.optimize(x, value);
  } catch (const std::exception&) {
    // NLopt reports roundoff-limited stops as exceptions; x holds the best point found.
  }
  if (value > s.best_drop) {
    for (size_t a = 0; a < cont.size(); ++a) s.best[cont[a]] = x[a];
    s.best_drop = value;
  }
}

}  // namespace

double Diagnosis::search_shape(Candidate& c, const Fit& current) {
  const std::string where = "diagnose candidate " + std::string(c.plugin->name) + " on joint '" + c.joint_name + "'";
  auto evaluate = [&](const std::vector<double>& shape, BlockColumns* keep) -> Gain {
    try {
      PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, shape), where);
      BlockColumns cols = columns(inst, fit_);
      Gain g = gain_of(cols, current.Q(), current.residual);
      if (keep) *keep = std::move(cols);
      // A shape where the fit leaves the effect's form (fs < fc) is no candidate shape: the
      // search looks for the best one inside it.
      if (!keep && g.rank > 0 && !outside_its_form(c, g.coef).empty()) return Gain{};
      return g;
    } catch (const PluginError&) {
      return Gain{};   // a shape the plugin refuses (lower >= upper): not a candidate
    }
  };
  const size_t ns = c.shape.size();
  if (ns == 0) {
    if (!c.searched) {
      PluginInstance inst(*c.plugin, reg_->model(), {c.joint}, config_of(c, {}), where);
      c.fit_cols = columns(inst, fit_);
      c.searched = true;
    }
    c.gain = gain_of(c.fit_cols, current.Q(), current.residual);
    return c.gain.rss_drop;
  }
  ShapeSearch s{evaluate, c, ns == 1 ? 40 : ns == 2 ? 16 : 6, {}, -1};
  const auto axes = grid_axes(c, s.per_axis);
  grid_scan(s, axes, one_thread(c));
  if (s.best_drop < 0) {
    c.gain = Gain{};
    return 0;
  }
  std::vector<size_t> cont;
  for (size_t k = 0; k < ns; ++k)
    if (!c.shape[k]->integer && axes[k].size() > 1) cont.push_back(k);
  zoom(s, cont);
  plateau_middle(s, cont);
  polish(s, cont);
  c.shape_values = s.best;
  c.gain = evaluate(s.best, &c.fit_cols);
  c.searched = true;
  return c.gain.rss_drop;
}

}  // namespace spml::diagnose_detail
