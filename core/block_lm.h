// Sparse Gauss-Newton / Levenberg-Marquardt for problems made of many small blocks of unknowns
// (one per sample, interval or static) coupled only through shared parameters:
//
//   minimise C(x_1..x_N, p) = sum_n |r_n(x_n, p)|^2      (r_n whitened: C = -2 log L + const)
//
// with x_n of a small fixed tangent dimension B and p of runtime dimension P. The normal
// equations are block-arrow shaped; each iteration eliminates every B x B block by a Schur
// complement onto p, solves the P x P reduced system, and back-substitutes the blocks:
//
//   S = H_pp - sum_n H_pn H_nn^-1 H_np,   S dp = g_p - sum_n H_pn H_nn^-1 g_n,
//   dx_n = H_nn^-1 (g_n - H_np dp),      with H = J^T J, g = -J^T r (Marquardt-damped).
//
// S at mu = 0 is the Fisher information of p with the blocks as nuisance parameters, and S^-1
// the Cramer-Rao bound of p (ComputeSharedInformation). Time O(N (B^3 + B q^2)) + O(P^3) per
// iteration, memory O(N B) besides the problem's own data: H_nn is rebuilt, never stored.
//
// Cost: O(max_iterations · (N (B^3 + B q^2) + P^3)) time, O(N B + (N / chunk) q^2) memory; the
// iterations are capped (max_iterations, and at most log(max_damping / min_damping) / log(
// damping_increase) rejected steps in a row), and options.stop is polled every 16 blocks.
//
// Coupling in compressed form: the problem writes H_np = w C_n L with a B x q matrix C_n per
// block, a q x P "lift" L common to all blocks and a scalar w, so the per-block work is on q x q
// sums whatever P is (the positions-only array: q = 12 for any number of triads, because a
// triad's Jacobian is affine in its position). The general case is q = P, L = I, w = 1
// (JacobianBlockProblem below builds it from raw Jacobians).
//
// A Problem is any class with these members (templates: no virtual calls in the inner loops):
//
//   static constexpr int kBlockDim;       // B, tangent dimension of one block (fixed)
//   static constexpr int kBlockStateDim;  // size of a block's stored state (>= B: manifolds)
//   static constexpr int kCouplingDim;    // q, or Eigen::Dynamic (then CouplingDim() says)
//   using SharedState = ...;              // any copyable type holding p
//   using Context = ...;                  // what the blocks need of p, computed once per point
//   using Sums = ...;                     // the problem's per-chunk sums (H_pp, g_p, extras)
//   int64_t NumBlocks() const;
//   int SharedDim() const;                // P (tangent dimension of p)
//   int CouplingDim() const;              // q
//   Context MakeContext(const SharedState& p) const;
//   Sums MakeSums() const;                // zero sums
//   void Merge(const Sums& from, Sums* into) const;  // into += from (called in chunk order)
//   // Undamped H_nn, g_n, C_n and the block's cost |r_n|^2 at (x_n, p); adds the block's
//   // contributions to H_pp and g_p (in whatever form) to *sums.
//   void Linearize(int64_t n, const BlockState& x, const Context& c, BlockNormal* out,
//                  Sums* sums) const;
//   // The same H_nn and C_n as Linearize (g and cost not needed): the back-substitution.
//   void BlockMatrices(int64_t n, const BlockState& x, const Context& c, BlockNormal* out) const;
//   double Cost(int64_t n, const BlockState& x, const Context& c) const;  // |r_n|^2
//   // Called in ComputeSharedInformation only, with L_n^-1 of H_nn = L_n L_n^T (may do nothing;
//   // e.g. leverages for degrees of freedom: H_nn^-1 = L_n^-T L_n^-1).
//   void Factored(int64_t n, const BlockMatrix& L_inverse, Sums* sums) const;
//   // Undamped H_pp (P x P), g_p (P), lift L (q x P) and weight w from the merged sums.
//   void AssembleShared(const Sums& sums, const Context& c, SharedNormal* out) const;
//   BlockState PlusBlock(const BlockState& x, const BlockVector& dx) const;        // x [+] dx
//   // Optional, runtime q only (declare static constexpr bool kStructuredCouplingGram = true):
//   // adds C_n^T H_nn^-1 C_n (H_nn = L L^T, given L^-1 of the possibly damped H_nn; at least
//   // the lower triangle) to *T from the block's structure, or returns false to leave it to
//   // the dense rank-k update. Equal to the dense term up to rounding.
//   bool AddCouplingGram(int64_t n, const BlockState& x, const Context& c,
//                        const BlockMatrix& L_inverse, Eigen::MatrixXd* T) const;
//   SharedState PlusShared(const SharedState& p, const Eigen::VectorXd& dp) const;  // p [+] dp
//   double SharedMaxNorm(const SharedState& p) const;  // scale of the step tolerance
//
// Determinism: blocks are processed in fixed chunks of options.chunk and every sum is reduced in
// chunk order, so results are bit-identical for any thread count or executor.
// Thread-safety: the solver calls the problem's const members concurrently from several threads.
#ifndef CALIBD_CORE_BLOCK_LM_H_
#define CALIBD_CORE_BLOCK_LM_H_

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/stop_token.h"

namespace calibd::core {

// ----- Execution: the one place where the numerics start threads.

// Runs run(0) ... run(tasks - 1), each exactly once, possibly concurrently, and returns when all
// have finished. A caller may pass its own (e.g. a shared pool) in BlockLmOptions::executor.
using TaskExecutor = std::function<void(int64_t tasks, const std::function<void(int64_t)>& run)>;

// Built-in executor: min(threads, tasks) threads (the caller's among them) take task indices
// from a shared counter; threads <= 0 means std::thread::hardware_concurrency().
void RunTasksOnThreads(int threads, int64_t tasks, const std::function<void(int64_t)>& run);

// Splits [0, n) into fixed chunks [c * chunk, min(n, (c + 1) * chunk)) and runs
// fn(c, begin, end) for every chunk through the executor (or the built-in threads).
class ChunkRunner {
 public:
  static constexpr int64_t kDefaultChunk = 256;
  ChunkRunner(int threads, TaskExecutor executor, int64_t chunk = kDefaultChunk)
      : threads_(threads), executor_(std::move(executor)), chunk_(chunk > 0 ? chunk : 1) {}

  int64_t NumChunks(int64_t n) const { return (n + chunk_ - 1) / chunk_; }

  template <class Fn>
  void ForEachChunk(int64_t n, Fn&& fn) const {
    const int64_t chunks = NumChunks(n);
    const std::function<void(int64_t)> task = [&](int64_t c) {
      fn(c, c * chunk_, std::min(n, (c + 1) * chunk_));
    };
    if (executor_)
      executor_(chunks, task);
    else
      RunTasksOnThreads(threads_, chunks, task);
  }

 private:
  int threads_;
  TaskExecutor executor_;
  int64_t chunk_;
};

// ----- Small dense Cholesky with fixed-size loops (Eigen's general solvers cost more than the
// arithmetic at B <= 12). A non-positive pivot gives NaN, which the solver's finiteness checks
// catch.
template <int B>
Eigen::Matrix<double, B, B> CholeskyFactor(const Eigen::Matrix<double, B, B>& H) {
  Eigen::Matrix<double, B, B> L = Eigen::Matrix<double, B, B>::Zero();
  for (int j = 0; j < B; ++j) {
    double d = H(j, j);
    for (int k = 0; k < j; ++k) d -= L(j, k) * L(j, k);
    const double ljj = std::sqrt(d);  // NaN when d < 0
    L(j, j) = ljj;
    for (int i = j + 1; i < B; ++i) {
      double v = H(i, j);
      for (int k = 0; k < j; ++k) v -= L(i, k) * L(j, k);
      L(i, j) = v / ljj;
    }
  }
  return L;
}

// H^-1 b by forward and back substitution with the Cholesky factor L of H.
template <int B>
Eigen::Matrix<double, B, 1> CholeskySolve(const Eigen::Matrix<double, B, B>& L,
                                          Eigen::Matrix<double, B, 1> b) {
  for (int i = 0; i < B; ++i) {
    for (int k = 0; k < i; ++k) b(i) -= L(i, k) * b(k);
    b(i) /= L(i, i);
  }
  for (int i = B - 1; i >= 0; --i) {
    for (int k = i + 1; k < B; ++k) b(i) -= L(k, i) * b(k);
    b(i) /= L(i, i);
  }
  return b;
}

// L^-1 for H = L L^T (lower triangular). Inlined into the Schur pass (as a call it costs 5-8 %
// of an array calibration).
#if defined(__GNUC__)
#define CALIBD_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define CALIBD_ALWAYS_INLINE inline
#endif
template <int B>
CALIBD_ALWAYS_INLINE Eigen::Matrix<double, B, B> InverseCholeskyFactor(
    const Eigen::Matrix<double, B, B>& H) {
  const Eigen::Matrix<double, B, B> L = CholeskyFactor<B>(H);
  Eigen::Matrix<double, B, B> Li = Eigen::Matrix<double, B, B>::Zero();
  for (int j = 0; j < B; ++j) {
    Li(j, j) = 1 / L(j, j);
    for (int i = j + 1; i < B; ++i) {
      double v = 0;
      for (int k = j; k < i; ++k) v -= L(i, k) * Li(k, j);
      Li(i, j) = v / L(i, i);
    }
  }
  return Li;
}

// ----- Options and summary.

struct BlockLmOptions {
  // LM iterations (accepted or rejected steps). Reaching it is not a failure. >= 1.
  int max_iterations = 50;
  // Converged when an accepted step decreases C by at most cost_tolerance * C. 0 = off. [0, 1).
  double cost_tolerance = 1e-10;
  // Converged when a step moves p by at most step_tolerance * (SharedMaxNorm(p) +
  // step_tolerance) in max-norm (accepted or not). 0 = off. [0, 1).
  double step_tolerance = 1e-10;
  // Converged when the max-norm of the gradient of C at a linearisation point is at most
  // gradient_tolerance times its value at the start. 0 = off. [0, 1).
  double gradient_tolerance = 0;
  // Marquardt damping: the diagonal of J^T J is multiplied by (1 + mu). mu starts at
  // initial_damping, is divided by damping_decrease after an accepted step (not below
  // min_damping) and multiplied by damping_increase after a rejected one; above max_damping the
  // solver stops (kNoProgress, or kNumericalFailure when no trial point had a finite cost).
  // 0 < min_damping <= initial_damping <= max_damping; factors > 1.
  double initial_damping = 1e-8;
  double min_damping = 1e-15;
  double max_damping = 1e10;
  double damping_decrease = 10;
  double damping_increase = 10;
  // Blocks per chunk: the unit of parallel work and of the ordered reductions. Results depend on
  // it (rounding) but not on the thread count. Per-chunk sums are kept until reduced, so memory
  // is (N / chunk) x (q^2 + the problem's Sums). >= 1.
  int64_t chunk = ChunkRunner::kDefaultChunk;
  // Worker threads when no executor is given; 0 = std::thread::hardware_concurrency(). >= 0.
  int threads = 1;
  // Optional: runs the chunks instead of the built-in threads (e.g. a shared pool).
  TaskExecutor executor;
  // Polled (core/stop_token.h) every iteration and every 16 blocks of every pass over the
  // blocks: when it asks, Solve returns at once with kUserStopped (x, p: the last accepted
  // point) and ComputeSharedInformation leaves partial sums (the caller checks the token).
  // Null: never stops.
  const StopToken* stop = nullptr;

  bool IsValid(std::string* error) const;
};

enum class BlockLmTermination {
  kNotRun,             // sentinel
  kCostTolerance,      // converged: relative cost decrease below cost_tolerance
  kStepTolerance,      // converged: step below step_tolerance
  kGradientTolerance,  // converged: gradient below gradient_tolerance
  kNoProgress,         // damping exceeded max_damping: no step decreases the cost (an optimum
                       // to working precision)
  kMaxIterations,      // iteration limit: the estimate is usable but not converged
  kUserStopped,        // the callback returned false, or options.stop asked
  kNumericalFailure,   // non-finite cost at the start, or no finite trial point at any damping
};
const char* BlockLmTerminationName(BlockLmTermination termination);

struct BlockLmSummary {
  BlockLmTermination termination = BlockLmTermination::kNotRun;
  int iterations = 0;                    // LM iterations, accepted or not
  int accepted_iterations = 0;           // of which the step was accepted
  std::vector<double> cost;              // C at the start and after every iteration
  double damping = 0;                    // mu at the end
  double initial_gradient_max_norm = 0;  // max-norm of the gradient of C at the start
  double gradient_max_norm = 0;          // the same at the last linearisation

  double initial_cost() const { return cost.empty() ? 0 : cost.front(); }
  double final_cost() const { return cost.empty() ? 0 : cost.back(); }
  // Tolerance met, or no further decrease possible.
  bool converged() const;
  // The estimate may be used (converged, iteration limit or stopped by the caller).
  bool usable() const;
  // One line: termination, iterations, cost.
  std::string BriefReport() const;
};

// Reduced normal equations of one block; see the Problem contract above.
template <int B, int Q>
struct BlockNormal {
  Eigen::Matrix<double, B, B> H;  // J_n^T J_n (undamped)
  Eigen::Matrix<double, B, 1> g;  // -J_n^T r_n
  Eigen::Matrix<double, B, Q> C;  // H_np = coupling_weight * C * lift
  double cost = 0;                // |r_n|^2
};

struct SharedNormal {
  Eigen::MatrixXd H;     // P x P, J_p^T J_p summed over the blocks (undamped)
  Eigen::VectorXd g;     // P, -J_p^T r
  Eigen::MatrixXd lift;  // q x P
  double coupling_weight = 1;
};

// True when Problem declares kStructuredCouplingGram (the optional AddCouplingGram above).
template <class P, class = void>
struct HasStructuredCouplingGram : std::false_type {};
template <class P>
struct HasStructuredCouplingGram<P, std::void_t<decltype(P::kStructuredCouplingGram)>>
    : std::bool_constant<P::kStructuredCouplingGram> {};

// The reduced (Schur) system at the final point, with mu = 0.
struct BlockLmInformation {
  Eigen::MatrixXd information;  // P x P Fisher information of p (blocks eliminated)
  Eigen::VectorXd gradient;     // P, reduced -J^T r (zero at the optimum)
  double cost = 0;
};

// Inverse of a Fisher information (the Cramer-Rao bound); false (and *covariance empty) when
// it is not positive definite.
bool InvertInformation(const Eigen::MatrixXd& information, Eigen::MatrixXd* covariance);

// ----- The solver.
template <class Problem>
class BlockLm {
 public:
  static constexpr int B = Problem::kBlockDim;
  static constexpr int S = Problem::kBlockStateDim;
  static constexpr int Q = Problem::kCouplingDim;
  using BlockStates = Eigen::Matrix<double, S, Eigen::Dynamic>;  // column n: x_n
  using SharedState = typename Problem::SharedState;
  using Context = typename Problem::Context;
  using Sums = typename Problem::Sums;
  using Normal = BlockNormal<B, Q>;
  using BlockMatrix = Eigen::Matrix<double, B, B>;
  using BlockVector = Eigen::Matrix<double, B, 1>;
  using QMatrix = Eigen::Matrix<double, Q, Q>;
  using QVector = Eigen::Matrix<double, Q, 1>;
  // Called after every accepted step with the iteration number and p; false stops the solver.
  using Callback = std::function<bool(int iteration, const SharedState& p)>;

  // options must be valid (BlockLmOptions::IsValid). Keeps a reference to problem.
  BlockLm(const Problem& problem, const BlockLmOptions& options)
      : problem_(problem),
        options_(options),
        runner_(options.threads, options.executor, options.chunk) {}

  // Minimises C from (*x, *p); on return they hold the estimate (the last accepted point).
  BlockLmSummary Solve(BlockStates* x, SharedState* p, const Callback& callback = {}) {
    BlockLmSummary summary;
    const int64_t N = problem_.NumBlocks();
    g_.resize(B, N);
    BlockStates x_trial(S, N);
    double mu = options_.initial_damping;
    Context context = problem_.MakeContext(*p);
    Linearization lin;
    Linearize(*x, context, mu, /*evaluate=*/true, /*information=*/false, &lin);
    double cost = lin.cost;
    summary.cost.push_back(cost);
    summary.gradient_max_norm = lin.gradient_max_norm;
    summary.initial_gradient_max_norm = lin.gradient_max_norm;
    const double gradient0 = lin.gradient_max_norm;
    if (StopRequested(options_.stop)) {
      summary.termination = BlockLmTermination::kUserStopped;
      g_.resize(B, 0);
      return summary;
    }
    if (!std::isfinite(cost)) {
      summary.termination = BlockLmTermination::kNumericalFailure;
      return summary;
    }
    const double stol = options_.step_tolerance;
    auto small_step = [&](double step, const SharedState& at) {
      return stol > 0 && step <= stol * (problem_.SharedMaxNorm(at) + stol);
    };
    BlockLmTermination termination = BlockLmTermination::kMaxIterations;
    bool finite_trial_since_accept = false;
    int it = 1;
    for (; it <= options_.max_iterations; ++it) {
      if (StopRequested(options_.stop)) {
        termination = BlockLmTermination::kUserStopped;
        --it;
        break;
      }
      if (options_.gradient_tolerance > 0 &&
          lin.gradient_max_norm <= options_.gradient_tolerance * gradient0) {
        termination = BlockLmTermination::kGradientTolerance;
        --it;
        break;
      }
      Eigen::MatrixXd Sred;
      Eigen::VectorXd rhs;
      ReducedSystem(lin, mu, &Sred, &rhs);
      const Eigen::LLT<Eigen::MatrixXd> llt(Sred);
      bool accepted = false;
      double step = std::numeric_limits<double>::infinity();
      if (llt.info() == Eigen::Success) {
        const Eigen::VectorXd dp = llt.solve(rhs);
        if (dp.allFinite()) {
          SharedState p_trial = problem_.PlusShared(*p, dp);
          Context context_trial = problem_.MakeContext(p_trial);
          const QVector dz = lin.shared.lift * dp;
          const double trial_cost =
              Step(*x, context, context_trial, dz, lin.shared.coupling_weight, mu, &x_trial);
          if (StopRequested(options_.stop)) {  // the trial is incomplete: never accepted
            termination = BlockLmTermination::kUserStopped;
            break;
          }
          step = dp.cwiseAbs().maxCoeff();
          if (std::isfinite(trial_cost)) finite_trial_since_accept = true;
          if (std::isfinite(trial_cost) && trial_cost < cost) {
            accepted = true;
            ++summary.accepted_iterations;
            finite_trial_since_accept = false;
            const double decrease = cost - trial_cost;
            cost = trial_cost;
            *p = std::move(p_trial);
            context = std::move(context_trial);
            x->swap(x_trial);
            mu = std::max(mu / options_.damping_decrease, options_.min_damping);
            summary.cost.push_back(cost);
            if (callback && !callback(it, *p)) {
              termination = BlockLmTermination::kUserStopped;
              break;
            }
            if (options_.cost_tolerance > 0 && decrease <= options_.cost_tolerance * cost) {
              termination = BlockLmTermination::kCostTolerance;
              break;
            }
            if (small_step(step, *p)) {
              termination = BlockLmTermination::kStepTolerance;
              break;
            }
          }
        }
      }
      if (!accepted) {
        summary.cost.push_back(cost);
        if (small_step(step, *p)) {
          termination = BlockLmTermination::kStepTolerance;
          break;
        }
        mu *= options_.damping_increase;
        if (mu > options_.max_damping) {
          termination = finite_trial_since_accept ? BlockLmTermination::kNoProgress
                                                  : BlockLmTermination::kNumericalFailure;
          break;
        }
      }
      if (it == options_.max_iterations) break;
      // Relinearise after an accepted step; after a rejected one only the damping changed, so
      // the stored gradients and shared sums are reused and only the blocks are refactored.
      Linearize(*x, context, mu, /*evaluate=*/accepted, /*information=*/false, &lin);
      if (accepted) summary.gradient_max_norm = lin.gradient_max_norm;
      if (StopRequested(options_.stop)) {
        termination = BlockLmTermination::kUserStopped;
        break;
      }
    }
    summary.iterations = std::min(it, options_.max_iterations);
    summary.termination = termination;
    summary.damping = mu;
    g_.resize(B, 0);
    return summary;
  }

  // Reduced Fisher information of p at (x, p) (mu = 0); *sums receives the problem's sums of
  // that pass (including what Factored added).
  void ComputeSharedInformation(const BlockStates& x, const SharedState& p,
                                BlockLmInformation* info, Sums* sums) {
    const Context context = problem_.MakeContext(p);
    Linearization lin;
    Linearize(x, context, 0.0, /*evaluate=*/true, /*information=*/true, &lin);
    ReducedSystem(lin, 0.0, &info->information, &info->gradient);
    info->cost = lin.cost;
    if (sums) *sums = std::move(lin.sums);
  }

 private:
  struct Linearization {
    QMatrix T;  // sum_n C_n^T H_nn^-1 C_n
    QVector t;  // sum_n C_n^T H_nn^-1 g_n
    double cost = 0;
    double gradient_max_norm = 0;  // of the gradient of C = -2 g
    Sums sums;
    SharedNormal shared;
  };

  struct ChunkSums {
    QMatrix T;
    QVector t;
    double cost = 0;
    double g_max = 0;
    Sums sums;
  };

  // evaluate: residuals, gradients and shared sums at x (stored in g_ and lin); otherwise only
  // the blocks are refactored with the new damping (g_, cost and sums kept).
  void Linearize(const BlockStates& x, const Context& context, double mu, bool evaluate,
                 bool information, Linearization* lin) {
    const int q = problem_.CouplingDim();
    std::vector<ChunkSums> chunks(runner_.NumChunks(problem_.NumBlocks()));
    runner_.ForEachChunk(problem_.NumBlocks(), [&](int64_t c, int64_t begin, int64_t end) {
      ChunkSums& acc = chunks[c];
      acc.T.setZero(q, q);
      acc.t.setZero(q);
      if (evaluate) acc.sums = problem_.MakeSums();
      Normal b;
      b.C.resize(B, q);
      Eigen::Matrix<double, B, Q> Z(B, q);
      // Runtime q (large): the Z of up to kStack blocks are stacked and their Z^T Z added by one
      // symmetric rank-k update of the lower triangle (half the flops of Z^T Z, and a k large
      // enough for the blocked kernel); symmetrised after the chunk reduction.
      constexpr int kStack = 16;
      Eigen::MatrixXd Zs;
      int stacked = 0;
      if constexpr (Q == Eigen::Dynamic) Zs.resize(B * kStack, q);
      auto flush = [&]() {
        if constexpr (Q == Eigen::Dynamic) {
          if (stacked > 0)
            acc.T.template selfadjointView<Eigen::Lower>().rankUpdate(
                Zs.topRows(B * stacked).transpose());
          stacked = 0;
        }
      };
      for (int64_t n = begin; n < end; ++n) {
        if (((n - begin) & 15) == 0 && StopRequested(options_.stop)) break;
        if (evaluate) {
          problem_.Linearize(n, x.col(n), context, &b, &acc.sums);
          acc.cost += b.cost;
          if (!information) g_.col(n) = b.g;
          acc.g_max = std::max(acc.g_max, b.g.cwiseAbs().maxCoeff());
        } else {
          problem_.BlockMatrices(n, x.col(n), context, &b);
          b.g = g_.col(n);
        }
        const BlockVector& g = b.g;
        if (mu > 0) b.H.diagonal() *= (1 + mu);
        // H = L L^T; with Z = L^-1 C and u = L^-1 g: C^T H^-1 C = Z^T Z, C^T H^-1 g = Z^T u.
        const BlockMatrix Linv = InverseCholeskyFactor<B>(b.H);
        const BlockVector u = Linv.lazyProduct(g);
        bool structured = false;
        if constexpr (Q == Eigen::Dynamic && HasStructuredCouplingGram<Problem>::value)
          structured = problem_.AddCouplingGram(n, x.col(n), context, Linv, &acc.T);
        if (structured) {
          // C^T H^-1 g = C^T (L^-T u).
          const BlockVector v = Linv.transpose().lazyProduct(u);
          acc.t.noalias() += b.C.transpose() * v;
        } else if constexpr (Q == Eigen::Dynamic) {
          Z = Linv.lazyProduct(b.C);
          Zs.middleRows(B * stacked, B) = Z;
          if (++stacked == kStack) flush();
          acc.t.noalias() += Z.transpose() * u;
        } else {
          Z = Linv.lazyProduct(b.C);
          acc.T.noalias() += Z.transpose().lazyProduct(Z);
          acc.t.noalias() += Z.transpose().lazyProduct(u);
        }
        if (information) problem_.Factored(n, Linv, &acc.sums);
      }
      flush();
    });
    lin->T.setZero(q, q);
    lin->t.setZero(q);
    if (evaluate) {
      lin->cost = 0;
      lin->sums = problem_.MakeSums();
    }
    double g_max = 0;
    for (const ChunkSums& acc : chunks) {
      lin->T += acc.T;
      lin->t += acc.t;
      if (evaluate) {
        lin->cost += acc.cost;
        g_max = std::max(g_max, acc.g_max);
        problem_.Merge(acc.sums, &lin->sums);
      }
    }
    if constexpr (Q == Eigen::Dynamic) lin->T = lin->T.template selfadjointView<Eigen::Lower>();
    if (evaluate) {
      problem_.AssembleShared(lin->sums, context, &lin->shared);
      const double gp = lin->shared.g.size() ? lin->shared.g.cwiseAbs().maxCoeff() : 0.0;
      lin->gradient_max_norm = 2 * std::max(g_max, gp);
    }
  }

  void ReducedSystem(const Linearization& lin, double mu, Eigen::MatrixXd* Sred,
                     Eigen::VectorXd* rhs) const {
    const SharedNormal& sh = lin.shared;
    const double w = sh.coupling_weight;
    Eigen::MatrixXd Hpp = sh.H;
    if (mu > 0) Hpp.diagonal() *= (1 + mu);
    *Sred = Hpp - (w * w) * (sh.lift.transpose() * lin.T * sh.lift);
    *rhs = sh.g - w * (sh.lift.transpose() * lin.t);
    *Sred = 0.5 * (*Sred + Sred->transpose());
  }

  // Back-substitution dx_n = H_nn^-1 (g_n - w C_n dz) and the cost at the trial point.
  double Step(const BlockStates& x, const Context& context, const Context& context_trial,
              const QVector& dz, double w, double mu, BlockStates* x_trial) {
    std::vector<double> sums(runner_.NumChunks(problem_.NumBlocks()), 0.0);
    const int q = problem_.CouplingDim();
    runner_.ForEachChunk(problem_.NumBlocks(), [&](int64_t c, int64_t begin, int64_t end) {
      Normal b;
      b.C.resize(B, q);
      double cost = 0;
      for (int64_t n = begin; n < end; ++n) {
        if (((n - begin) & 15) == 0 && StopRequested(options_.stop)) break;
        problem_.BlockMatrices(n, x.col(n), context, &b);
        if (mu > 0) b.H.diagonal() *= (1 + mu);
        BlockVector rhs;
        if constexpr (Q == Eigen::Dynamic)
          rhs = g_.col(n) - w * (b.C * dz);
        else
          rhs = g_.col(n) - w * b.C.lazyProduct(dz);
        const BlockVector dx = CholeskySolve<B>(CholeskyFactor<B>(b.H), rhs);
        x_trial->col(n) = problem_.PlusBlock(x.col(n), dx);
        cost += problem_.Cost(n, x_trial->col(n), context_trial);
      }
      sums[c] = cost;
    });
    double total = 0;
    for (double s : sums) total += s;
    return total;
  }

  const Problem& problem_;
  BlockLmOptions options_;
  ChunkRunner runner_;
  Eigen::Matrix<double, B, Eigen::Dynamic> g_;  // g_n of the current linearisation
};

// ----- Raw-Jacobian adaptor: the general case q = P, lift = I.
//
// Functor contract:
//   static constexpr int kBlockDim, kBlockStateDim;
//   static constexpr int kResidualDim;    // m per block, fixed
//   int64_t NumBlocks() const;
//   int SharedDim() const;                // P (state and tangent of p are Eigen::VectorXd)
//   // r_n (m), and when J_x, J_p are not null their Jacobians w.r.t. the tangents of x_n (m x B)
//   // and of p (m x P, already sized).
//   void Evaluate(int64_t n, const BlockState& x, const Eigen::VectorXd& p, Residual* r,
//                 JacobianX* J_x, Eigen::Matrix<double, m, Eigen::Dynamic>* J_p) const;
//   BlockState PlusBlock(const BlockState& x, const BlockVector& dx) const;
//   Eigen::VectorXd PlusShared(const Eigen::VectorXd& p, const Eigen::VectorXd& dp) const;
template <class Functor>
class JacobianBlockProblem {
 public:
  static constexpr int kBlockDim = Functor::kBlockDim;
  static constexpr int kBlockStateDim = Functor::kBlockStateDim;
  static constexpr int kCouplingDim = Eigen::Dynamic;
  static constexpr int M = Functor::kResidualDim;
  using SharedState = Eigen::VectorXd;
  using BlockState = Eigen::Matrix<double, kBlockStateDim, 1>;
  using BlockVector = Eigen::Matrix<double, kBlockDim, 1>;
  using BlockMatrix = Eigen::Matrix<double, kBlockDim, kBlockDim>;
  using Residual = Eigen::Matrix<double, M, 1>;
  using JacobianX = Eigen::Matrix<double, M, kBlockDim>;
  using JacobianP = Eigen::Matrix<double, M, Eigen::Dynamic>;
  using Normal = BlockNormal<kBlockDim, Eigen::Dynamic>;
  struct Context {
    Eigen::VectorXd p;
  };
  struct Sums {
    Eigen::MatrixXd H;
    Eigen::VectorXd g;
  };

  explicit JacobianBlockProblem(const Functor& f) : f_(f) {}  // keeps a reference to f

  int64_t NumBlocks() const { return f_.NumBlocks(); }
  int SharedDim() const { return f_.SharedDim(); }
  int CouplingDim() const { return f_.SharedDim(); }
  Context MakeContext(const SharedState& p) const { return Context{p}; }
  Sums MakeSums() const {
    const int P = SharedDim();
    return Sums{Eigen::MatrixXd::Zero(P, P), Eigen::VectorXd::Zero(P)};
  }
  void Merge(const Sums& from, Sums* into) const {
    into->H += from.H;
    into->g += from.g;
  }
  template <class X>
  void Linearize(int64_t n, const X& x, const Context& c, Normal* out, Sums* sums) const {
    Residual r;
    JacobianX Jx;
    JacobianP Jp(M, SharedDim());
    f_.Evaluate(n, BlockState(x), c.p, &r, &Jx, &Jp);
    out->H.noalias() = Jx.transpose() * Jx;
    out->g.noalias() = -Jx.transpose() * r;
    out->C.noalias() = Jx.transpose() * Jp;
    out->cost = r.squaredNorm();
    sums->H.noalias() += Jp.transpose() * Jp;
    sums->g.noalias() -= Jp.transpose() * r;
  }
  template <class X>
  void BlockMatrices(int64_t n, const X& x, const Context& c, Normal* out) const {
    Residual r;
    JacobianX Jx;
    JacobianP Jp(M, SharedDim());
    f_.Evaluate(n, BlockState(x), c.p, &r, &Jx, &Jp);
    out->H.noalias() = Jx.transpose() * Jx;
    out->C.noalias() = Jx.transpose() * Jp;
  }
  template <class X>
  double Cost(int64_t n, const X& x, const Context& c) const {
    Residual r;
    f_.Evaluate(n, BlockState(x), c.p, &r, nullptr, nullptr);
    return r.squaredNorm();
  }
  void Factored(int64_t, const BlockMatrix&, Sums*) const {}
  void AssembleShared(const Sums& sums, const Context&, SharedNormal* out) const {
    out->H = sums.H;
    out->g = sums.g;
    out->lift = Eigen::MatrixXd::Identity(SharedDim(), SharedDim());
    out->coupling_weight = 1;
  }
  template <class X, class D>
  BlockState PlusBlock(const X& x, const D& dx) const {
    return f_.PlusBlock(BlockState(x), BlockVector(dx));
  }
  SharedState PlusShared(const SharedState& p, const Eigen::VectorXd& dp) const {
    return f_.PlusShared(p, dp);
  }
  double SharedMaxNorm(const SharedState& p) const {
    return p.size() ? p.cwiseAbs().maxCoeff() : 0.0;
  }

 private:
  const Functor& f_;
};

}  // namespace calibd::core

#endif  // CALIBD_CORE_BLOCK_LM_H_
