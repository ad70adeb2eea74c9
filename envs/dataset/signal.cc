#include "spml/signal.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "spml/parse.h"
#include <stdexcept>

namespace spml {

using Section = Eigen::Matrix<double, 5, 1>;

std::vector<Section> butterworth_lowpass(int order, double cutoff_hz, double rate_hz) {
  if (order < 2 || order % 2) throw std::invalid_argument("Butterworth order must be even and >= 2");
  if (!(cutoff_hz > 0 && cutoff_hz < 0.5 * rate_hz))
    throw std::invalid_argument("low-pass cut-off must lie between 0 and half the sampling rate");
  // Analog prototype poles in conjugate pairs; each pair is s^2 + 2 sin(theta) s + 1 in
  // normalised frequency. Pre-warp the cut-off, then map s -> K (z - 1) / (z + 1).
  const double K = 1.0 / std::tan(M_PI * cutoff_hz / rate_hz);   // = 2 fs / wc_warped, wc normalised to 1
  std::vector<Section> sos;
  for (int k = 0; k < order / 2; ++k) {
    const double theta = M_PI * (2.0 * k + 1.0) / (2.0 * order);
    const double c = 2.0 * std::sin(theta);   // s^2 + c s + 1
    const double a0 = K * K + c * K + 1.0;
    Section s;
    s << 1.0 / a0, 2.0 / a0, 1.0 / a0, 2.0 * (1.0 - K * K) / a0, (K * K - c * K + 1.0) / a0;
    sos.push_back(s);
  }
  return sos;
}

namespace {

// One second-order section in transposed direct form II: y from input u, state (z1, z2).
inline double section_step(const Section& s, double u, double& z1, double& z2) {
  const double y = s[0] * u + z1;
  z1 = s[1] * u - s[3] * y + z2;
  z2 = s[2] * u - s[4] * y;
  return y;
}

// A section's state at the steady state for a constant input u0 (every section has unity DC gain).
inline void steady(const Section& s, double u0, double& z1, double& z2) { z1 = u0 * (1.0 - s[0]), z2 = u0 * (s[2] - s[4]); }

// One pass of the cascade, each section started at the steady state for a constant input
// equal to its first input. Sections go through the record in pairs: the two recursions are
// independent from one sample to the next, so the processor overlaps them (a section alone
// waits on its own state; diagnose filters simulated forces along whole logs thousands of
// times). The same operations in the same order per section as one section at a time.
void cascade(const std::vector<Section>& sos, std::vector<double>& x) {
  if (x.empty()) return;
  size_t k = 0;
  for (; k + 1 < sos.size(); k += 2) {
    const Section &a = sos[k], &b = sos[k + 1];
    double a1, a2, b1, b2;
    steady(a, x[0], a1, a2);
    const double y0 = section_step(a, x[0], a1, a2);
    steady(b, y0, b1, b2);
    x[0] = section_step(b, y0, b1, b2);
    for (size_t i = 1; i < x.size(); ++i) x[i] = section_step(b, section_step(a, x[i], a1, a2), b1, b2);
  }
  if (k < sos.size()) {
    double z1, z2;
    steady(sos[k], x[0], z1, z2);
    for (double& v : x) v = section_step(sos[k], v, z1, z2);
  }
}

}  // namespace

Eigen::Index settling_samples(const std::vector<Section>& sos) {
  // The cascade's impulse response, on a record doubled until its last sample above 1e-6 of
  // the peak lies in the record's first half (a low cut-off rings for many samples).
  constexpr Eigen::Index kMax = 1 << 20;
  std::vector<double> h(256, 0.0);
  h[1] = 1.0;   // after a zero: the cascade starts at rest
  for (;;) {
    std::vector<double> y = h;
    cascade(sos, y);
    double peak = 0;
    for (double v : y) peak = std::max(peak, std::fabs(v));
    Eigen::Index last = 0;
    for (size_t i = 0; i < y.size(); ++i)
      if (std::fabs(y[i]) > 1e-6 * peak) last = static_cast<Eigen::Index>(i);
    if (2 * last < static_cast<Eigen::Index>(y.size()) || static_cast<Eigen::Index>(y.size()) >= kMax) return last + 1;
    h.resize(2 * h.size(), 0.0);
  }
}

Eigen::VectorXd filtfilt(const std::vector<Section>& sos, const Eigen::VectorXd& x, Eigen::Index reflect) {
  const Eigen::Index n = x.size();
  if (n < 2) return x;
  const Eigen::Index pad = std::min<Eigen::Index>(n - 1, reflect >= 0 ? reflect : 3 * 2 * static_cast<Eigen::Index>(sos.size()));
  std::vector<double> ext;
  ext.reserve(static_cast<size_t>(n + 2 * pad));
  for (Eigen::Index i = pad; i >= 1; --i) ext.push_back(2.0 * x[0] - x[i]);            // odd reflection
  for (Eigen::Index i = 0; i < n; ++i) ext.push_back(x[i]);
  for (Eigen::Index i = n - 2; i >= n - 1 - pad; --i) ext.push_back(2.0 * x[n - 1] - x[i]);
  cascade(sos, ext);
  std::reverse(ext.begin(), ext.end());
  cascade(sos, ext);
  std::reverse(ext.begin(), ext.end());
  return Eigen::Map<const Eigen::VectorXd>(ext.data() + pad, n);
}

Eigen::VectorXd central_difference(const Eigen::VectorXd& x, double dt) {
  const Eigen::Index n = x.size();
  Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
  if (n < 2) return d;
  for (Eigen::Index i = 1; i + 1 < n; ++i) d[i] = (x[i + 1] - x[i - 1]) / (2.0 * dt);
  d[0] = (x[1] - x[0]) / dt;
  d[n - 1] = (x[n - 1] - x[n - 2]) / dt;
  return d;
}

double median_step(const Eigen::VectorXd& t) {
  std::vector<double> steps;
  for (Eigen::Index i = 1; i < t.size(); ++i) steps.push_back(t[i] - t[i - 1]);
  if (steps.empty()) return 0;
  std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2), steps.end());
  return steps[steps.size() / 2];
}

bool uneven_steps(const Eigen::VectorXd& t) {
  const double m = median_step(t);
  for (Eigen::Index i = 1; i < t.size(); ++i)
    if (std::fabs((t[i] - t[i - 1]) - m) > 0.01 * m) return true;
  return false;
}

Eigen::VectorXd interpolate(const Eigen::VectorXd& t, const Eigen::VectorXd& x, const Eigen::VectorXd& at) {
  Eigen::VectorXd out(at.size());
  Eigen::Index k = 0;
  for (Eigen::Index i = 0; i < at.size(); ++i) {
    while (k + 2 < t.size() && t[k + 1] < at[i]) ++k;
    const double w = (at[i] - t[k]) / (t[k + 1] - t[k]);
    out[i] = x[k] + std::clamp(w, 0.0, 1.0) * (x[k + 1] - x[k]);
  }
  return out;
}

std::string lowpass_record_text(const LowpassRecord& f) {
  std::ostringstream s;
  s.precision(17);
  s << "butterworth order=" << f.order << " cutoff=" << f.cutoff_hz << " zero-phase";
  return s.str();
}

std::optional<LowpassRecord> parse_lowpass_record(const std::string& text) {
  std::istringstream in(text);
  std::string kind, order, cutoff, phase, extra;
  if (!(in >> kind >> order >> cutoff >> phase) || (in >> extra)) return std::nullopt;
  if (kind != "butterworth" || phase != "zero-phase" || order.rfind("order=", 0) != 0 || cutoff.rfind("cutoff=", 0) != 0) return std::nullopt;
  LowpassRecord f;
  try {
    size_t used = 0;
    f.order = std::stoi(order.substr(6), &used);
    if (used != order.size() - 6) return std::nullopt;
    f.cutoff_hz = std::stod(cutoff.substr(7), &used);
    if (used != cutoff.size() - 7) return std::nullopt;
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (f.order < 2 || f.order % 2 || !(f.cutoff_hz > 0) || !std::isfinite(f.cutoff_hz)) return std::nullopt;
  return f;
}

std::string decimation_record_text(const DecimationRecord& d) {
  return "keep=" + std::to_string(d.keep) + (d.anti_alias ? " after " + lowpass_record_text(*d.anti_alias) : std::string(" plain"));
}

std::optional<DecimationRecord> parse_decimation_record(const std::string& text) {
  const auto space = text.find(' ');
  if (text.rfind("keep=", 0) != 0 || space == std::string::npos) return std::nullopt;
  DecimationRecord d;
  try {
    size_t used = 0;
    d.keep = std::stoi(text.substr(5, space - 5), &used);
    if (used != space - 5 || d.keep < 1) return std::nullopt;
  } catch (const std::exception&) {
    return std::nullopt;
  }
  const std::string rest = text.substr(space + 1);
  if (rest == "plain") return d;
  if (rest.rfind("after ", 0) != 0 || !(d.anti_alias = parse_lowpass_record(rest.substr(6)))) return std::nullopt;
  return d;
}

std::optional<double> quantization_step(const Eigen::VectorXd& x) {
  std::vector<double> d;
  for (Eigen::Index i = 1; i < x.size(); ++i)
    if (const double step = std::fabs(x[i] - x[i - 1]); step > 0) d.push_back(step);
  if (d.size() < 20) return std::nullopt;
  const double smallest = *std::min_element(d.begin(), d.end());
  // The smallest change, refined as the mean of the single steps, must divide all the others.
  size_t whole = 0, single = 0;
  double sum_single = 0;
  for (double step : d) {
    const double k = std::round(step / smallest);
    if (std::fabs(step / smallest - k) > 0.01) continue;
    ++whole;
    if (k == 1) ++single, sum_single += step;
  }
  if (static_cast<double>(whole) < 0.999 * static_cast<double>(d.size()) || single == 0) return std::nullopt;
  return sum_single / static_cast<double>(single);
}

std::string position_steps_text(const std::map<std::string, double>& steps) {
  std::string out;
  for (const auto& [name, step] : steps) out += (out.empty() ? "" : " ") + name + "=" + exact_text(step);
  return out;
}

std::map<std::string, double> parse_position_steps(const std::string& text) {
  std::map<std::string, double> out;
  std::istringstream in(text);
  for (std::string item; in >> item;) {
    const auto eq = item.rfind('=');
    const auto v = eq == std::string::npos ? std::nullopt : parse_number(item.substr(eq + 1));
    if (!v || !(*v > 0) || eq == 0) return {};
    out[item.substr(0, eq)] = *v;
  }
  return out;
}

namespace {

// The import's low-pass at `rate_hz` (none, or one at or above half the rate: the column as it is).
Eigen::VectorXd lowpassed_like_import(const Eigen::VectorXd& raw, double rate_hz, const std::optional<LowpassRecord>& lowpass) {
  return lowpass && lowpass->cutoff_hz < 0.5 * rate_hz ? filtfilt(butterworth_lowpass(lowpass->order, lowpass->cutoff_hz, rate_hz), raw) : raw;
}

// The decimation's anti-alias pass and every keep-th sample.
Eigen::VectorXd decimated_like_import(Eigen::VectorXd v, double rate_hz, const DecimationRecord& decimation) {
  if (decimation.anti_alias && decimation.anti_alias->cutoff_hz < 0.5 * rate_hz)
    v = filtfilt(butterworth_lowpass(decimation.anti_alias->order, decimation.anti_alias->cutoff_hz, rate_hz), v);
  const int keep = std::max(decimation.keep, 1);
  Eigen::VectorXd kept((v.size() + keep - 1) / keep);
  for (Eigen::Index i = 0; i < kept.size(); ++i) kept[i] = v[i * keep];
  return kept;
}

}  // namespace

DerivedSignals derive_like_import(const Eigen::VectorXd& raw, double rate_hz, const std::optional<LowpassRecord>& lowpass, const DecimationRecord& decimation,
                                  const Eigen::VectorXd* velocity, const Eigen::VectorXd* acceleration) {
  DerivedSignals d;
  d.q = lowpassed_like_import(raw, rate_hz, lowpass);
  d.qd = velocity ? lowpassed_like_import(*velocity, rate_hz, lowpass) : central_difference(d.q, 1 / rate_hz);
  d.qdd = acceleration ? lowpassed_like_import(*acceleration, rate_hz, lowpass) : central_difference(d.qd, 1 / rate_hz);
  for (auto* v : {&d.q, &d.qd, &d.qdd}) *v = decimated_like_import(std::move(*v), rate_hz, decimation);
  return d;
}

Eigen::VectorXd condition_like_import(const Eigen::VectorXd& raw, double rate_hz, const std::optional<LowpassRecord>& lowpass, const DecimationRecord& decimation) {
  return decimated_like_import(lowpassed_like_import(raw, rate_hz, lowpass), rate_hz, decimation);
}

}  // namespace spml
