// The coverage of the sphere by the field directions of CalibratePca (core/pca.h): how evenly
// the positions spread (PcaCoverage) and, when poorly, which orientations to add.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/pca_internal.h"

namespace calibd::core::pca_internal {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// Caps of PcaCoverage: within 60° of an axis direction, within 30° of an edge direction.
constexpr double kAxisCapCos = 0.5;
constexpr double kEdgeCapCos = 0.8660254037844386;
constexpr const char* kAxisName[3] = {"x", "y", "z"};
constexpr int kPairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};  // the axis pairs of the edge caps

// The field directions scaled to unit length (d×n); false when one is zero.
bool UnitDirections(const MatrixXd& v, MatrixXd* u) {
  const int n = static_cast<int>(v.cols());
  *u = v;
  for (int j = 0; j < n; ++j) {
    const double norm = u->col(j).norm();
    if (!(norm > 0)) return false;
    u->col(j) /= norm;
  }
  return true;
}

// Σ_j f_j f_jᵀ / n of the quadric fit's design on the unit directions u (d×n).
MatrixXd QuadricDesign(const MatrixXd& u, bool with_bias) {
  const int d = static_cast<int>(u.rows());
  const int n = static_cast<int>(u.cols());
  const int nq = d * (d + 1) / 2;
  const int nf = nq + (with_bias ? d : 0);
  MatrixXd f(nf, n);
  for (int j = 0; j < n; ++j) {
    int idx = 0;
    for (int k = 0; k < d; ++k) {
      for (int l = k; l < d; ++l) f(idx++, j) = (k == l ? 1.0 : std::sqrt(2.0)) * u(k, j) * u(l, j);
    }
    if (with_bias) f.col(j).tail(d) = u.col(j);
  }
  MatrixXd design = MatrixXd::Zero(nf, nf);
  design.selfadjointView<Eigen::Lower>().rankUpdate(f, 1.0 / n);
  design = design.selfadjointView<Eigen::Lower>();
  return design;
}

// The same design's expectation for directions uniform on the sphere.
MatrixXd UniformDesign(int d, bool with_bias) {
  const int nq = d * (d + 1) / 2;
  const int nf = nq + (with_bias ? d : 0);
  // Its expectation for uniform directions: E u_k⁴ = 3/(d(d+2)), E u_k²u_l² = 1/(d(d+2)),
  // E u_k² = 1/d, odd moments 0.
  MatrixXd uniform = MatrixXd::Zero(nf, nf);
  const double q = 1.0 / (d * (d + 2.0));
  std::vector<int> diag_index;
  int idx = 0;
  for (int k = 0; k < d; ++k) {
    for (int l = k; l < d; ++l, ++idx) {
      if (k == l) {
        diag_index.push_back(idx);
      } else {
        uniform(idx, idx) = 2 * q;
      }
    }
  }
  for (int k : diag_index) {
    for (int l : diag_index) uniform(k, l) = (k == l ? 3 : 1) * q;
  }
  if (with_bias) uniform.bottomRightCorner(d, d).diagonal().setConstant(1.0 / d);
  return uniform;
}

// The spread of the unit directions, measured against a uniform spread: what the verdict and the
// advice are drawn from.
struct Spread {
  MatrixXd u;                                        // d×n unit field directions
  Eigen::SelfAdjointEigenSolver<MatrixXd> scatter;   // of u uᵀ / n
  MatrixXd li;                                       // L⁻¹, L the Cholesky factor of the uniform
                                                     // design
  Eigen::SelfAdjointEigenSolver<MatrixXd> relative;  // of L⁻¹ design L⁻ᵀ
  int nq = 0;                                        // quadratic terms of the design (first)
  bool poor_scatter = false;                         // scatter_min below kMinScatter
  bool poor_design = false;                          // design_min below kMinDesign
};

// Fills cov's scatter_eigenvalues, scatter_min, design_min and verdict, and the rest of *spread,
// from spread->u (d×n unit directions).
void MeasureSpread(bool with_bias, PcaCoverage* cov, Spread* spread) {
  const MatrixXd& u = spread->u;
  const int d = static_cast<int>(u.rows());
  const int n = static_cast<int>(u.cols());
  spread->scatter.compute(u * u.transpose() / n);
  cov->scatter_eigenvalues = spread->scatter.eigenvalues();
  cov->scatter_min = d * std::max(0.0, cov->scatter_eigenvalues(0));
  spread->nq = d * (d + 1) / 2;
  const int nf = spread->nq + (with_bias ? d : 0);
  const MatrixXd design = QuadricDesign(u, with_bias);
  const Eigen::LLT<MatrixXd> llt(UniformDesign(d, with_bias));
  spread->li = llt.matrixL().solve(MatrixXd::Identity(nf, nf));
  const MatrixXd& li = spread->li;
  spread->relative.compute(li * design * li.transpose());
  cov->design_min = std::max(0.0, spread->relative.eigenvalues()(0));
  spread->poor_scatter = cov->scatter_min < PcaCoverage::kMinScatter;
  spread->poor_design = cov->design_min < PcaCoverage::kMinDesign;
  cov->verdict = spread->poor_scatter || spread->poor_design ? PcaCoverageVerdict::kPoor
                                                             : PcaCoverageVerdict::kGood;
}

// d = 3: cov's cap_names and cap_positions from the unit directions u (3×n).
void CountCaps(const MatrixXd& u, PcaCoverage* cov_out) {
  PcaCoverage& cov = *cov_out;
  const int n = static_cast<int>(u.cols());
  // d = 3: positions near each axis direction and between each pair of axes.
  std::vector<Eigen::Vector3d> dirs;
  for (int k = 0; k < 3; ++k) {
    for (int sgn : {1, -1}) {
      cov.cap_names.push_back(std::string(sgn > 0 ? "+" : "-") + kAxisName[k]);
      dirs.push_back(sgn * Eigen::Vector3d::Unit(k));
    }
  }
  for (const auto& pr : kPairs) {
    for (int s1 : {1, -1}) {
      for (int s2 : {1, -1}) {
        cov.cap_names.push_back(std::string(s1 > 0 ? "+" : "-") + kAxisName[pr[0]] +
                                (s2 > 0 ? "+" : "-") + kAxisName[pr[1]]);
        dirs.push_back((s1 * Eigen::Vector3d::Unit(pr[0]) + s2 * Eigen::Vector3d::Unit(pr[1])) /
                       std::sqrt(2.0));
      }
    }
  }
  cov.cap_positions.assign(dirs.size(), 0);
  for (int j = 0; j < n; ++j) {
    for (size_t c = 0; c < dirs.size(); ++c) {
      const double cos_angle = u.col(j).dot(dirs[c]);
      if (cos_angle >= (c < 6 ? kAxisCapCos : kEdgeCapCos)) ++cov.cap_positions[c];
    }
  }
}

// d = 3, a poor verdict: cov's advice, naming the orientations to add in the frame of frame_note.
void AdviseOrientations(const Spread& spread, const std::string& frame_note, PcaCoverage* cov_out) {
  PcaCoverage& cov = *cov_out;
  const MatrixXd& u = spread.u;
  const int n = static_cast<int>(u.cols());
  const int nq = spread.nq;
  const bool poor_scatter = spread.poor_scatter, poor_design = spread.poor_design;
  const auto& scatter = spread.scatter;
  const auto& relative = spread.relative;
  const MatrixXd& li = spread.li;
  std::vector<std::string> parts;
  std::vector<bool> named(6, false);
  auto name_axis = [&](int k, int sign_index) {  // sign_index 0: +, 1: −
    if (named[2 * k + sign_index]) return;
    named[2 * k + sign_index] = true;
    parts.push_back(std::string("with the ") + (sign_index == 0 ? "+" : "-") + kAxisName[k] +
                    " axis up");
  };
  // Axis directions with no position near them, both signs together where both are missing.
  for (int k = 0; k < 3; ++k) {
    const bool plus = cov.cap_positions[2 * k] == 0, minus = cov.cap_positions[2 * k + 1] == 0;
    if (plus && minus) {
      named[2 * k] = named[2 * k + 1] = true;
      parts.push_back(std::string("with the +") + kAxisName[k] + " and with the -" + kAxisName[k] +
                      " axis up");
    } else if (plus || minus) {
      name_axis(k, plus ? 0 : 1);
    }
  }
  // The sparser side of an axis: the one with fewer positions near it.
  auto sparse_side = [&](int k) {
    return cov.cap_positions[2 * k] <= cov.cap_positions[2 * k + 1] ? 0 : 1;
  };
  if (poor_scatter) {
    // The sparse direction is the eigenvector of the smallest scatter eigenvalue.
    Eigen::Index k;
    scatter.eigenvectors().col(0).cwiseAbs().maxCoeff(&k);
    if (!named[2 * k] && !named[2 * k + 1]) {
      named[2 * k] = named[2 * k + 1] = true;
      parts.push_back(std::string("with the +") + kAxisName[k] + " and with the -" + kAxisName[k] +
                      " axis up");
    }
  }
  if (poor_design) {
    // Pairs of axes with (almost) no position in between: the information on their u_k u_l term
    // (the angle between the axes), Σ_j 2 u_k² u_l² / n, below 0.3 of its uniform expectation
    // 2/15.
    std::vector<int> empty_pairs;
    for (int pi = 0; pi < 3; ++pi) {
      const auto uk = u.row(kPairs[pi][0]).array(), ul = u.row(kPairs[pi][1]).array();
      const double info = 2 * (uk * uk * ul * ul).sum() / n;
      if (info < 0.3 * 2.0 / 15.0) empty_pairs.push_back(pi);
    }
    if (empty_pairs.empty()) {
      // The weakest direction of the design: its largest term names what is missing.
      const VectorXd w = li.transpose() * relative.eigenvectors().col(0);
      Eigen::Index k;
      w.cwiseAbs().maxCoeff(&k);
      if (k >= nq) {  // a linear term (bias): the sparse side of that axis
        name_axis(static_cast<int>(k - nq), sparse_side(static_cast<int>(k - nq)));
      } else {
        int fidx = 0;
        for (int a = 0; a < 3; ++a) {
          for (int b = a; b < 3; ++b, ++fidx) {
            if (fidx != k) continue;
            if (a == b) {
              name_axis(a, sparse_side(a));
            } else {
              for (int pi = 0; pi < 3; ++pi) {
                if (kPairs[pi][0] == a && kPairs[pi][1] == b) empty_pairs.push_back(pi);
              }
            }
          }
        }
      }
    }
    if (!empty_pairs.empty()) {
      std::string list;
      for (size_t i = 0; i < empty_pairs.size(); ++i) {
        const int pi = empty_pairs[i];
        list += std::string(i == 0                        ? ""
                            : i + 1 == empty_pairs.size() ? " and "
                                                          : ", ") +
                "the " + kAxisName[kPairs[pi][0]] + " and " + kAxisName[kPairs[pi][1]] + " axes";
      }
      const int p0 = empty_pairs[0];
      parts.push_back("tilted about 45 degrees between " + list + " (e.g. with the +" +
                      kAxisName[kPairs[p0][0]] + "+" + kAxisName[kPairs[p0][1]] + " direction up)");
    }
  }
  if (parts.empty()) parts.push_back("spread over the whole sphere");
  cov.advice = "add positions ";
  for (size_t i = 0; i < parts.size(); ++i) {
    cov.advice += (i == 0 ? "" : i + 1 == parts.size() ? ", and " : ", ") + parts[i];
  }
  cov.advice += " (" + frame_note + ")";
}

}  // namespace

PcaCoverage Coverage(const MatrixXd& v, bool with_bias, const std::string& frame_note) {
  PcaCoverage cov;
  const int d = static_cast<int>(v.rows());
  const int n = static_cast<int>(v.cols());
  if (n < 1 || d < 1 || !v.allFinite()) return cov;
  Spread spread;
  if (!UnitDirections(v, &spread.u)) return cov;
  MeasureSpread(with_bias, &cov, &spread);
  if (d != 3) {
    if (cov.verdict == PcaCoverageVerdict::kPoor) {
      cov.advice =
          "add positions with the field in directions between and opposite to those recorded, "
          "spread over the whole sphere";
    }
    return cov;
  }
  CountCaps(spread.u, &cov);
  if (cov.verdict != PcaCoverageVerdict::kPoor) return cov;
  AdviseOrientations(spread, frame_note, &cov);
  return cov;
}

void CoverageFromNominal(const MatrixXd& mm, const PcaOptions& options, PcaResult* result) {
  if (!options.nominal || options.nominal->cols() != mm.rows() || mm.cols() < 1) return;
  const MatrixXd& nom = *options.nominal;
  const Eigen::LDLT<MatrixXd> gram(nom * nom.transpose());
  if (gram.info() != Eigen::Success || !(gram.rcond() > 1e-12)) return;
  const MatrixXd v = gram.solve(nom * mm);
  result->coverage = Coverage(v, options.bias == BiasModel::kEstimate,
                              "axes of the nominal frame, through the nominal sensitivities");
}

}  // namespace calibd::core::pca_internal
