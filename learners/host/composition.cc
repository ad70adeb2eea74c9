#include "spml/learners/composition.h"

#include <algorithm>

#include "spml/parse.h"

namespace spml {
namespace {

class Composition : public Learner {
 public:
  Composition(std::string name, std::unique_ptr<Learner> a, std::unique_ptr<Learner> b, bool iterative)
      : name_(std::move(name)), a_(std::move(a)), b_(std::move(b)), iterative_(iterative) {}
  std::string name() const override { return name_; }
  std::uint32_t flags() const override {
    const std::uint32_t fa = a_->flags(), fb = b_->flags();
    constexpr std::uint32_t kEither =
        SPML_LEARNER_USES_MODEL | SPML_LEARNER_VARIANCE | SPML_LEARNER_NEEDS_PRIOR | SPML_LEARNER_NEEDS_TRUTH;
    // Progress always: the stages' ends are known even when neither part reports inside a fit.
    return ((fa | fb) & kEither) | (fa & fb & SPML_LEARNER_DETERMINISTIC) | SPML_LEARNER_PROGRESS;
  }
  void fit(const LearnerData& train, const LearnerModel& model, const LearnerConfig& config) override {
    int iterations = iterative_ ? kDefaultIterations : 1;
    for (const auto& [k, v] : config.values)
      if (k == "iterations" && iterative_) {
        const auto n = parse_integer(v, 1, 1000);
        if (!n) throw LearnerError(name_ + ": config 'iterations' must be a whole number in [1, 1000], got '" + v + "'");
        iterations = static_cast<int>(*n);
      }
    const RowMatrix& y = *train.Y;
    LearnerData part = train;
    RowMatrix target = y, residual;
    // Progress: fit k of the n = 2 * iterations fits spans [k/n, (k+1)/n]; a part that reports
    // its own progress moves within its span, one that does not jumps to its span's end.
    const int stages = 2 * iterations;
    double reached = 0;   // the parts' fractions are each monotone; the scaled sequence is too
    auto stage_config = [&](int k, Learner& part_learner) {
      LearnerConfig c = config;
      c.progress = nullptr;
      if (config.progress && part_learner.reports_progress())
        c.progress = [&, k](double f, const char* stage) {
          reached = std::max(reached, (k + std::min(1.0, std::max(0.0, f))) / stages);
          const std::string text = part_learner.name() + ": " + stage;
          config.progress(reached, text.c_str());
        };
      return c;
    };
    auto stage_done = [&](int k) {
      reached = std::max(reached, static_cast<double>(k + 1) / stages);
      if (config.progress) config.progress(reached, k % 2 == 0 ? "first part fitted" : "residual part fitted");
    };
    if (config.progress) config.progress(0.0, "start");
    for (int it = 0; it < iterations; ++it) {
      if (it > 0) target = y - b_->predict(inputs_of(train)).mean;   // eq. 6: A on what B leaves
      part.Y = &target;
      a_->fit(part, model, stage_config(2 * it, *a_));
      stage_done(2 * it);
      residual = y - a_->predict(inputs_of(train)).mean;               // eq. 4: B on what A leaves
      part.Y = &residual;
      b_->fit(part, model, stage_config(2 * it + 1, *b_));
      stage_done(2 * it + 1);
    }
  }
  LearnerPrediction predict(const LearnerData& query) const override {
    LearnerPrediction pa = a_->predict(query), pb = b_->predict(query);
    LearnerPrediction p;
    p.mean = pa.mean + pb.mean;   // eq. 5
    if (pa.var.size() && pb.var.size()) p.var = pa.var + pb.var;
    else if (pb.var.size()) p.var = pb.var;
    else if (pa.var.size()) p.var = pa.var;
    return p;
  }
  std::string notes() const override {
    std::string n;
    for (const Learner* l : {a_.get(), b_.get()}) {
      const std::string s = l->notes();
      if (!s.empty()) n += (n.empty() ? "" : "; ") + l->name() + ": " + s;
    }
    return n;
  }
  Eigen::VectorXd coefficients() const override { return a_->coefficients(); }

 private:
  static LearnerData inputs_of(const LearnerData& d) {
    LearnerData q = d;
    q.Y = nullptr;
    return q;
  }
  std::string name_;
  std::unique_ptr<Learner> a_, b_;
  bool iterative_;
};

}  // namespace

std::unique_ptr<Learner> make_composition(std::string name, std::unique_ptr<Learner> a, std::unique_ptr<Learner> b,
                                          bool iterative) {
  return std::make_unique<Composition>(std::move(name), std::move(a), std::move(b), iterative);
}

}  // namespace spml
