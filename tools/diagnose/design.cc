#include "design.h"
#include "parallel.h"
#include "statistics.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

namespace spml::diagnose_detail {

// A direction counts as new when at least this fraction of its (unit) norm lies outside the
// span of the columns already there: well above rounding, well below any real effect.
constexpr double kRankTolerance = 1e-6;

namespace {

// The pseudo-inverse of a Gram matrix G of columns scaled to unit norm (scale: 1 / their norms,
// 0 for a zero column), without the directions whose eigenvalue is at most kRankTolerance^2 -
// the same test of a new direction as fit_blocks' pivots. For gain_of (G the columns' part
// outside the current basis) and rss_of (the whole design).
struct UnitGramInverse {
  Eigen::VectorXd scale;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig;
  Eigen::VectorXd inv;   // 1 / eigenvalue, 0 for the directions left out
  int rank = 0;
  UnitGramInverse(const Eigen::MatrixXd& G, const Eigen::VectorXd& squared_norms) : scale(squared_norms.cwiseSqrt()) {
    for (Eigen::Index k = 0; k < scale.size(); ++k) scale[k] = scale[k] > 0 ? 1.0 / scale[k] : 0.0;
    eig.compute(scale.asDiagonal() * G * scale.asDiagonal());
    inv = eig.eigenvalues();
    for (Eigen::Index k = 0; k < inv.size(); ++k) {
      inv[k] = inv[k] > kRankTolerance * kRankTolerance ? 1.0 / inv[k] : 0.0;
      rank += inv[k] > 0;
    }
  }
  // The eigen-coordinates of the scaled right-hand side D rhs.
  Eigen::VectorXd project(const Eigen::VectorXd& rhs) const { return eig.eigenvectors().transpose() * (scale.asDiagonal() * rhs); }
  // D (D G D)^+ D rhs: the least-squares coefficients of the unscaled columns.
  Eigen::VectorXd solve(const Eigen::VectorXd& rhs) const {
    return scale.asDiagonal() * (eig.eigenvectors() * inv.cwiseProduct(project(rhs)));
  }
};

}  // namespace

Eigen::MatrixXd BlockColumns::dense() const {
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(rows_per_output * outputs, cols);
  for (size_t a = 0; a < active.size(); ++a) M.middleRows(active[a] * rows_per_output, rows_per_output) = parts[a];
  return M;
}

Eigen::VectorXd BlockColumns::times(const Eigen::VectorXd& x) const {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(rows_per_output * outputs);
  for (size_t a = 0; a < active.size(); ++a) out.segment(active[a] * rows_per_output, rows_per_output) = parts[a] * x;
  return out;
}

BlockColumns BlockColumns::from_dense(const Eigen::MatrixXd& M, Eigen::Index rows_per_output, int outputs) {
  BlockColumns b;
  b.rows_per_output = rows_per_output;
  b.outputs = outputs;
  b.cols = static_cast<int>(M.cols());
  if (M.cols() == 0) return b;   // no parts (maxCoeff of an empty part is undefined)
  for (int o = 0; o < outputs; ++o) {
    auto part = M.middleRows(o * rows_per_output, rows_per_output);
    if (part.cwiseAbs().maxCoeff() == 0) continue;
    b.active.push_back(o);
    b.parts.emplace_back(part);
  }
  return b;
}

BlockBuilder::BlockBuilder(Eigen::Index rows_per_output, int outputs, int cols)
    : rows_(rows_per_output), cols_(cols), parts_(static_cast<size_t>(outputs)) {}

Eigen::MatrixXd& BlockBuilder::part(int output) {
  Eigen::MatrixXd& p = parts_[static_cast<size_t>(output)];
  if (p.size() == 0) p = Eigen::MatrixXd::Zero(rows_, cols_);
  return p;
}

bool BlockBuilder::all_finite() const {
  return std::all_of(parts_.begin(), parts_.end(), [](const Eigen::MatrixXd& p) { return p.allFinite(); });
}

namespace {

Eigen::MatrixXd dense_of(const std::vector<const BlockColumns*>& blocks, Eigen::Index rows) {
  Eigen::Index cols = 0;
  for (auto* b : blocks) cols += b->cols;
  Eigen::MatrixXd F(rows, cols);
  Eigen::Index c = 0;
  for (auto* b : blocks) {
    F.middleCols(c, b->cols) = b->dense();
    c += b->cols;
  }
  return F;
}

}  // namespace

// fit_blocks' factorization, kept for the basis: F's rows in chunks, F_c = Q_c R_c each (on
// the machine's cores), the stacked R_c = Qs R0, and the rank-revealing pivoted QR of the small
// R0 P = Q1 R. Every stage is orthogonal, so in exact arithmetic the pivots and the rank are
// those of one pivoted QR of F; where columns tie (one a multiple of another after scaling) or
// a pivot lies at the tolerance, rounding picks the column kept, in either. The residual and
// the prediction do not depend on that pick. The chunks follow the size of F alone, so the
// numbers are the same on any machine.
struct Factors {
  std::vector<Eigen::Index> starts;   // first row of each chunk, then the row count
  std::vector<Eigen::Index> stacked;  // first row of each chunk's R in the stack, then its row count
  std::vector<Eigen::HouseholderQR<Eigen::MatrixXd>> chunks;
  Eigen::HouseholderQR<Eigen::MatrixXd> stack;   // with more than one chunk
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> inner;
  Eigen::Index cols = 0, square = 0;
  int rank = 0;

  size_t count() const { return chunks.size(); }
  Eigen::Index rows_of(size_t c) const { return starts[c + 1] - starts[c]; }
  Eigen::Index top_of(size_t c) const { return std::min(cols, rows_of(c)); }

  void compute(const Eigen::MatrixXd& F) {
    cols = F.cols();
    // Chunks of 25 000 to 50 000 rows, at most four (longer designs get longer chunks): the
    // Householder sweeps of one chunk stay in cache far better than over 10^5 rows, and the
    // chunks factor in parallel.
    const auto n = std::clamp<Eigen::Index>(F.rows() / 25000, 1, 4);
    for (Eigen::Index c = 0; c <= n; ++c) starts.push_back(F.rows() * c / n);
    chunks.resize(static_cast<size_t>(n));
    parallel_for(chunks.size(), [&](size_t c) { chunks[c].compute(F.middleRows(starts[c], rows_of(c))); });
    square = std::min(cols, F.rows());
    stacked = {0};
    for (size_t c = 0; c < count(); ++c) stacked.push_back(stacked.back() + top_of(c));
    if (count() == 1) {
      inner.compute(chunks[0].matrixQR().topRows(square).triangularView<Eigen::Upper>());
      return;
    }
    Eigen::MatrixXd Rs(stacked.back(), cols);
    for (size_t c = 0; c < count(); ++c) Rs.middleRows(stacked[c], top_of(c)) = chunks[c].matrixQR().topRows(top_of(c)).triangularView<Eigen::Upper>();
    stack.compute(Rs);
    inner.compute(stack.matrixQR().topRows(square).triangularView<Eigen::Upper>());
  }
  // Q^T y, the first `rank` entries (Q the orthogonal factor of F P).
  Eigen::VectorXd adjoint_times(const Eigen::VectorXd& y) const {
    Eigen::VectorXd t(stacked.back());   // the square R0's rows when there is one chunk
    parallel_for(count(), [&](size_t c) {
      Eigen::VectorXd part = y.segment(starts[c], rows_of(c));
      part.applyOnTheLeft(chunks[c].householderQ().adjoint());
      t.segment(stacked[c], top_of(c)) = part.head(top_of(c));
    });
    if (count() > 1) t.applyOnTheLeft(stack.householderQ().adjoint());
    Eigen::VectorXd t1 = t.head(square);
    t1.applyOnTheLeft(inner.householderQ().adjoint());
    return t1.head(rank);
  }
  // The first `rank` columns of Q times top (rank x m).
  Eigen::MatrixXd basis_times(const Eigen::MatrixXd& top) const {
    Eigen::MatrixXd small = Eigen::MatrixXd::Zero(square, top.cols());
    small.topRows(rank) = top;
    small.applyOnTheLeft(inner.householderQ());
    Eigen::MatrixXd mid = small;
    if (count() > 1) {
      mid = Eigen::MatrixXd::Zero(stacked.back(), top.cols());
      mid.topRows(square) = small;
      mid.applyOnTheLeft(stack.householderQ());
    }
    Eigen::MatrixXd out(starts.back(), top.cols());
    parallel_for(count(), [&](size_t c) {
      Eigen::MatrixXd part = Eigen::MatrixXd::Zero(rows_of(c), top.cols());
      part.topRows(top_of(c)) = mid.middleRows(stacked[c], top_of(c));
      part.applyOnTheLeft(chunks[c].householderQ());
      out.middleRows(starts[c], rows_of(c)) = part;
    });
    return out;
  }
};

const Eigen::MatrixXd& Fit::Q() const {
  // Formed once even when the first calls come from several threads at once (the searches of
  // plugins that run on the cores, parallel.h); every call takes the lock, a cost far below the
  // simulation or projection each call serves.
  static std::mutex forming;
  std::lock_guard<std::mutex> lock(forming);
  if (!basis) {
    if (!factors) throw std::logic_error("Fit::Q: the fit was made without want_basis");
    basis = std::make_shared<const Eigen::MatrixXd>(factors->basis_times(Eigen::MatrixXd::Identity(rank, rank)));
  }
  return *basis;
}

Fit fit_blocks(const std::vector<const BlockColumns*>& blocks, const Eigen::VectorXd& y, bool want_basis, Eigen::Index hac_rows_per_output) {
  Eigen::MatrixXd F = dense_of(blocks, y.size());
  const Eigen::Index cols = F.cols();
  Fit fit;
  fit.coef = Eigen::VectorXd::Zero(cols);
  fit.stderr_ = Eigen::VectorXd::Constant(cols, std::numeric_limits<double>::infinity());
  fit.determined.assign(static_cast<size_t>(cols), false);
  if (cols == 0) {
    fit.residual = y;
    fit.rss = y.squaredNorm();
    fit.basis = std::make_shared<const Eigen::MatrixXd>(y.size(), 0);
    return fit;
  }
  Eigen::VectorXd scale = F.colwise().norm().transpose();
  for (Eigen::Index k = 0; k < cols; ++k) scale[k] = scale[k] > 0 ? scale[k] : 1.0;
  F *= scale.cwiseInverse().asDiagonal();
  // Not one column-pivoted QR of F, which sweeps all rows column by column (on the
  // undecimated Panda, 14 560 fit rows x 7 joints, it was half the run): see Factors.
  auto fac = std::make_shared<Factors>();
  fac->compute(F);
  // Rank from the pivots of the unit-norm columns (they fall monotonically).
  const Eigen::MatrixXd& R = fac->inner.matrixQR();
  int rank = 0;
  while (rank < fac->square && std::fabs(R(rank, rank)) > kRankTolerance) ++rank;
  fit.rank = fac->rank = rank;
  const auto& perm = fac->inner.colsPermutation().indices();
  const Eigen::VectorXd qty = fac->adjoint_times(y);
  const Eigen::MatrixXd R11 = R.topLeftCorner(rank, rank).triangularView<Eigen::Upper>();
  const Eigen::VectorXd z = R11.triangularView<Eigen::Upper>().solve(qty);
  fit.residual = y - fac->basis_times(qty).col(0);
  fit.rss = fit.residual.squaredNorm();
  const double dof = std::max<double>(1.0, static_cast<double>(y.size() - rank));
  const double sigma2 = fit.rss / dof;
  const Eigen::MatrixXd Rinv = R11.triangularView<Eigen::Upper>().solve(Eigen::MatrixXd::Identity(rank, rank));
  // Covariance of z = R11^-1 Q^T y: sigma^2 R11^-1 R11^-T for white residuals; with a long-run
  // covariance S of the rows q_i r_i, R11^-1 S R11^-T (sandwich), scaled by n / (n - rank).
  // The determined columns are F1 = Q R11, so q_i = R11^-T f_i: S from the rows f_i r_i,
  // mapped through R11^-1 (no basis needed).
  const Eigen::MatrixXd RR = Rinv * Rinv.transpose();
  Eigen::MatrixXd V_z;
  if (hac_rows_per_output > 0) {
    Eigen::MatrixXd Z(F.rows(), rank);
    for (int i = 0; i < rank; ++i) Z.col(i) = F.col(perm[i]).cwiseProduct(fit.residual);
    V_z = RR * long_run_covariance(Z, fit.residual, hac_rows_per_output) * RR * (static_cast<double>(y.size()) / dof);
    fit.robust = true;
  } else {
    V_z = sigma2 * RR;
  }
  fit.cov = Eigen::MatrixXd::Zero(cols, cols);
  for (int i = 0; i < rank; ++i) {
    const int k = perm[i];
    fit.coef[k] = z[i] / scale[k];
    fit.stderr_[k] = std::sqrt(std::max(V_z(i, i), 0.0)) / scale[k];
    fit.determined[static_cast<size_t>(k)] = true;
    for (int j = 0; j < rank; ++j) fit.cov(k, perm[j]) = V_z(i, j) / (scale[k] * scale[perm[j]]);
  }
  if (want_basis) fit.factors = std::move(fac);
  return fit;
}

double rss_of(const std::vector<const BlockColumns*>& blocks, const Eigen::VectorXd& y) {
  std::vector<Eigen::Index> off{0};
  for (auto* b : blocks) off.push_back(off.back() + b->cols);
  const Eigen::Index cols = off.back();
  if (cols == 0) return y.squaredNorm();
  // F^T F and F^T v block by block, over the outputs both blocks act on (the nuisance blocks
  // are one output each, so most of a dense F is zeros).
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(cols, cols);
  for (size_t b1 = 0; b1 < blocks.size(); ++b1) {
    const BlockColumns& B1 = *blocks[b1];
    for (size_t a1 = 0; a1 < B1.active.size(); ++a1) {
      // The diagonal block's lower triangle, then the blocks before it that act on this output.
      G.block(off[b1], off[b1], B1.cols, B1.cols).selfadjointView<Eigen::Lower>().rankUpdate(B1.parts[a1].transpose());
      for (size_t b2 = 0; b2 < b1; ++b2) {
        const BlockColumns& B2 = *blocks[b2];
        const auto a2 = std::find(B2.active.begin(), B2.active.end(), B1.active[a1]);
        if (a2 != B2.active.end())
          G.block(off[b1], off[b2], B1.cols, B2.cols).noalias() += B1.parts[a1].transpose() * B2.parts[static_cast<size_t>(a2 - B2.active.begin())];
      }
    }
  }
  G.triangularView<Eigen::StrictlyUpper>() = G.transpose();
  auto transpose_times = [&](const Eigen::VectorXd& v) {
    Eigen::VectorXd out = Eigen::VectorXd::Zero(cols);
    for (size_t b = 0; b < blocks.size(); ++b)
      for (size_t a = 0; a < blocks[b]->active.size(); ++a)
        out.segment(off[b], blocks[b]->cols).noalias() +=
            blocks[b]->parts[a].transpose() * v.segment(blocks[b]->active[a] * blocks[b]->rows_per_output, blocks[b]->rows_per_output);
    return out;
  };
  const UnitGramInverse Ginv(G, G.diagonal());
  Eigen::VectorXd coef = Ginv.solve(transpose_times(y));
  const Eigen::VectorXd r = y - predict_blocks(blocks, coef, y.size());
  coef += Ginv.solve(transpose_times(r));   // one step of refinement
  return (y - predict_blocks(blocks, coef, y.size())).squaredNorm();
}

Fit iv_fit_blocks(const std::vector<const BlockColumns*>& blocks, const std::vector<const BlockColumns*>& inst, const Eigen::VectorXd& y,
                  Eigen::Index hac_rows_per_output) {
  Fit fit = fit_blocks(blocks, y, false);
  std::vector<Eigen::Index> keep;
  for (size_t k = 0; k < fit.determined.size(); ++k)
    if (fit.determined[k]) keep.push_back(static_cast<Eigen::Index>(k));
  if (keep.empty()) return fit;
  const Eigen::MatrixXd Fall = dense_of(blocks, y.size()), Zall = dense_of(inst, y.size());
  const auto n = static_cast<Eigen::Index>(keep.size());
  Eigen::MatrixXd F(y.size(), n), Z(y.size(), n);
  Eigen::VectorXd scale(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    scale[k] = Fall.col(keep[static_cast<size_t>(k)]).norm();
    scale[k] = scale[k] > 0 ? scale[k] : 1.0;
    F.col(k) = Fall.col(keep[static_cast<size_t>(k)]) / scale[k];
    Z.col(k) = Zall.col(keep[static_cast<size_t>(k)]) / scale[k];
  }
  const Eigen::PartialPivLU<Eigen::MatrixXd> lu(Z.transpose() * F);
  const Eigen::VectorXd z = lu.solve(Z.transpose() * y);
  fit.residual = y - F * z;
  fit.rss = fit.residual.squaredNorm();
  const double dof = std::max<double>(1.0, static_cast<double>(y.size() - n));
  const Eigen::MatrixXd Pinv = lu.solve(Eigen::MatrixXd::Identity(n, n));   // (Z^T F)^-1
  // The sandwich (Z^T F)^-1 S (F^T Z)^-1: S the long-run covariance of the rows z_i r_i, or
  // sigma^2 Z^T Z for white residuals.
  const Eigen::MatrixXd S = hac_rows_per_output > 0
                                ? Eigen::MatrixXd(long_run_covariance(Z.array().colwise() * fit.residual.array(), fit.residual, hac_rows_per_output) *
                                                  (static_cast<double>(y.size()) / dof))
                                : Eigen::MatrixXd((fit.rss / dof) * Z.transpose() * Z);
  const Eigen::MatrixXd V = Pinv * S * Pinv.transpose();
  fit.robust = hac_rows_per_output > 0;
  fit.cov = Eigen::MatrixXd::Zero(Fall.cols(), Fall.cols());
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto c = keep[static_cast<size_t>(k)];
    fit.coef[c] = z[k] / scale[k];
    fit.stderr_[c] = std::sqrt(std::max(V(k, k), 0.0)) / scale[k];
    for (Eigen::Index l = 0; l < n; ++l) fit.cov(c, keep[static_cast<size_t>(l)]) = V(k, l) / (scale[k] * scale[l]);
    if (!std::isfinite(fit.coef[c]) || !std::isfinite(fit.stderr_[c])) {   // instruments blind to this column
      fit.determined[static_cast<size_t>(c)] = false;
      fit.coef[c] = 0;
      fit.stderr_[c] = std::numeric_limits<double>::infinity();
    }
  }
  for (Eigen::Index c = 0; c < fit.cov.rows(); ++c)
    if (!fit.determined[static_cast<size_t>(c)]) {
      fit.cov.row(c).setZero();
      fit.cov.col(c).setZero();
    }
  return fit;
}

Gain gain_of(const BlockColumns& C, const Eigen::MatrixXd& Q, const Eigen::VectorXd& r) {
  const Eigen::Index N = C.rows_per_output;
  // G = C^T C - (Q^T C)^T (Q^T C) and g = C^T r (r is orthogonal to Q), over the active rows only.
  Eigen::MatrixXd QtC = Eigen::MatrixXd::Zero(Q.cols(), C.cols), CtC = Eigen::MatrixXd::Zero(C.cols, C.cols);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(C.cols);
  for (size_t a = 0; a < C.active.size(); ++a) {
    const auto rows = C.active[a] * N;
    QtC.noalias() += Q.middleRows(rows, N).transpose() * C.parts[a];
    CtC.noalias() += C.parts[a].transpose() * C.parts[a];
    g.noalias() += C.parts[a].transpose() * r.segment(rows, N);
  }
  Gain out;
  if (C.cols == 0) return out;
  const UnitGramInverse Ginv(CtC - QtC.transpose() * QtC, CtC.diagonal());
  const Eigen::VectorXd proj = Ginv.project(g);
  out.rss_drop = proj.cwiseAbs2().dot(Ginv.inv);
  out.coef = Ginv.solve(g);
  out.rank = Ginv.rank;
  out.rss_drop = std::min(out.rss_drop, r.squaredNorm());
  return out;
}

Eigen::VectorXd predict_blocks(const std::vector<const BlockColumns*>& blocks, const Eigen::VectorXd& coef,
                               Eigen::Index rows) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(rows);
  Eigen::Index c = 0;
  for (auto* b : blocks) {
    out += b->times(coef.segment(c, b->cols));
    c += b->cols;
  }
  return out;
}

Eigen::VectorXd output_weights(const Eigen::VectorXd& r, Eigen::Index N) {
  const Eigen::Index outputs = N > 0 ? r.size() / N : 0;
  Eigen::VectorXd sigma(outputs), w = Eigen::VectorXd::Ones(outputs);
  for (Eigen::Index o = 0; o < outputs; ++o) sigma[o] = std::sqrt(r.segment(o * N, N).squaredNorm() / static_cast<double>(N));
  const double all = outputs > 0 ? std::sqrt(sigma.squaredNorm() / static_cast<double>(outputs)) : 0;
  if (!(all > 0) || !std::isfinite(all)) return w;
  for (Eigen::Index o = 0; o < outputs; ++o) w[o] = all / std::max(sigma[o], 1e-3 * all);
  // Normalised so that the residual r keeps its sum of squares: sum_o w_o^2 sigma_o^2 = sum_o sigma_o^2.
  double weighted = 0;
  for (Eigen::Index o = 0; o < outputs; ++o) weighted += w[o] * w[o] * sigma[o] * sigma[o];
  return weighted > 0 ? Eigen::VectorXd(w * std::sqrt(sigma.squaredNorm() / weighted)) : w;
}

Eigen::VectorXd scale_outputs(const Eigen::VectorXd& y, const Eigen::VectorXd& w, Eigen::Index N) {
  Eigen::VectorXd out = y;
  for (Eigen::Index o = 0; o < w.size() && (o + 1) * N <= out.size(); ++o) out.segment(o * N, N) *= w[o];
  return out;
}

void scale_outputs_in_place(Eigen::MatrixXd& M, const Eigen::VectorXd& w, Eigen::Index N) {
  for (Eigen::Index o = 0; o < w.size() && (o + 1) * N <= M.rows(); ++o) M.middleRows(o * N, N) *= w[o];
}

}  // namespace spml::diagnose_detail
