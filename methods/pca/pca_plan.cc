// The plan of a pca calibration (SPEC §10, Method::Plan): the σ CalibratePca would report for a
// protocol's orientations, what they cannot determine, and a suggested set of orientations.
//
// Predicted σ: CalibratePca itself on the readings the nominal sensors give, without noise, at
// the protocol's field directions (r_ij = a_iᵀ c u_j), with the config's noise_std. The fit then
// lands on the nominal exactly and its σ is the method's Cramér–Rao bound at nominal values: the
// σ a calibration of a recording of that protocol reports, within Monte-Carlo resolution
// (tests/server/plan_test.cc). noise_std is the σ of one averaged reading (SPEC §3), so the static
// duration and rate enter only through it.
//
// Undetermined: the null space of the method's reduced information (core::ComputePcaInformation)
// beyond its rotation gauge, mapped to parameter names; the missing directions from the design of
// the orientations (methods/plan.h MissingDirections).
//
// Suggested: greedy D-optimal design over the 26 candidate directions (methods/plan.h): from no
// position, add the candidate that most increases log det of the information (gauge fixed,
// regularised by 1e-6 while it is singular), until the predicted result passes the method's own
// gate (JudgePca with the limits in force) or kMaxSuggested positions, then naming the unmet rules.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <set>

#include "methods/pca/pca_method.h"
#include "methods/plan.h"

namespace calibd::server {
namespace {

using nlohmann::json;

constexpr int kMaxSuggested = 24;

// The sensors the plan is made for: the nominal (d×m) scaled to the largest column 1 (the design
// criterion does not depend on the scale).
Eigen::MatrixXd DesignSensitivities(const core::PcaOptions& options) {
  const Eigen::MatrixXd& a = *options.nominal;
  return a / a.colwise().norm().maxCoeff();
}

Eigen::MatrixXd Directions(const std::vector<Eigen::Vector3d>& orientations) {
  Eigen::MatrixXd u(3, static_cast<Eigen::Index>(orientations.size()));
  for (size_t j = 0; j < orientations.size(); ++j)
    u.col(static_cast<Eigen::Index>(j)) = orientations[j];
  return u;
}

// S + κ N Nᵀ: the information with its rotation gauge fixed (κ = the mean diagonal of S).
Eigen::MatrixXd GaugeFixedInformation(const core::PcaInformation& info) {
  const double trace = info.s.trace();
  const double kappa = trace > 0 ? trace / static_cast<double>(info.s.rows()) : 1.0;
  return info.s + kappa * info.gauge * info.gauge.transpose();
}

// The readings of the nominal sensors at the orientations, noise-free, and the method's result.
Status Predict(const core::PcaOptions& options, const std::vector<Eigen::Vector3d>& orientations,
               const std::vector<std::string>& sensor_names, results::PcaResult* out) {
  const double c = options.magnitude.value_or(1.0);
  core::PcaProblem problem;
  problem.m = options.nominal->transpose() * (c * Directions(orientations));
  problem.sensor_names = sensor_names;
  core::PcaResult r;
  Status s = core::CalibratePca(problem, options, &r);
  *out = MakePcaResult(r);
  return s;
}

std::string ParameterName(const std::string& sensor, int q) {
  return sensor + (q < 3 ? std::string(".sensitivity[") + "xyz"[q] + "]" : ".bias");
}

// The parameters in the null space of the gauge-fixed information (empty when regular).
std::vector<std::string> UndeterminedParameters(const core::PcaInformation& info, int p,
                                                const std::vector<std::string>& sensors) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(GaugeFixedInformation(info));
  const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
  std::vector<bool> involved(static_cast<size_t>(info.s.rows()), false);
  for (Eigen::Index k = 0; k < eig.eigenvalues().size(); ++k) {
    if (eig.eigenvalues()(k) > 1e-9 * largest) continue;
    const Eigen::VectorXd z = eig.eigenvectors().col(k);
    const double zmax = z.cwiseAbs().maxCoeff();
    for (Eigen::Index i = 0; i < z.size(); ++i) {
      if (std::abs(z(i)) > 0.1 * zmax) involved[static_cast<size_t>(i)] = true;
    }
  }
  std::vector<std::string> names;
  for (size_t i = 0; i < involved.size(); ++i) {
    if (involved[i]) names.push_back(ParameterName(sensors[i / p], static_cast<int>(i % p)));
  }
  return names;
}

double LogDetRegularised(const Eigen::MatrixXd& a, const std::vector<Eigen::Vector3d>& u,
                         core::BiasModel bias) {
  core::PcaInformation info;
  if (!core::ComputePcaInformation(a, Directions(u), bias, &info).ok()) return -INFINITY;
  Eigen::MatrixXd m = GaugeFixedInformation(info);
  m.diagonal().array() += 1e-6;
  Eigen::LLT<Eigen::MatrixXd> llt(m);
  if (llt.info() != Eigen::Success) return -INFINITY;
  return 2 * llt.matrixLLT().diagonal().array().log().sum();
}

// The predicted result of `orientations` and its verdict; false when the fit fails.
bool PredictAndJudge(const core::PcaOptions& options, const std::vector<Eigen::Vector3d>& u,
                     const std::vector<std::string>& sensors, const AcceptanceLimits& limits,
                     results::PcaResult* result, Verdict* verdict) {
  if (!Predict(options, u, sensors, result).ok()) return false;
  JudgePca(*result, options, limits, verdict);
  return true;
}

json Suggest(const core::PcaOptions& options, const std::vector<std::string>& sensors,
             const AcceptanceLimits& limits) {
  const Eigen::MatrixXd a = DesignSensitivities(options);
  std::vector<Eigen::Vector3d> chosen;
  std::vector<std::string> names;
  results::PcaResult result;
  Verdict verdict;
  bool predicted = false;
  while (static_cast<int>(chosen.size()) < kMaxSuggested) {
    double best = -INFINITY;
    const PlanCandidate* pick = &PlanCandidates().front();
    for (const PlanCandidate& c : PlanCandidates()) {
      chosen.push_back(c.direction);
      const double value = LogDetRegularised(a, chosen, options.bias);
      chosen.pop_back();
      if (value > best + 1e-9) {
        best = value;
        pick = &c;
      }
    }
    chosen.push_back(pick->direction);
    names.push_back(pick->name);
    verdict = Verdict();
    predicted = PredictAndJudge(options, chosen, sensors, limits, &result, &verdict);
    if (predicted && verdict.accepted()) break;
  }
  json out = {{"design",
               "greedy D-optimal over the 26 directions ±x, ±y, ±z, the 12 edge and "
               "8 corner diagonals (most log det of the information per added "
               "position), until the gate's limits are met or " +
                   std::to_string(kMaxSuggested) + " positions"},
              {"orientations", OrientationsJson(chosen, names)},
              {"meets_limits", predicted && verdict.accepted()},
              {"unmet", predicted ? verdict.reasons()
                                  : std::vector<std::string>{
                                        result.diagnostics.reason.value_or("the fit failed")}}};
  out["uncertainty"] = predicted ? results::ToJson(result)["uncertainty"] : json();
  return out;
}

}  // namespace

Status PlanPca(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
               json* out) {
  if (Status s = RequireOrientations(protocol); !s.ok()) return s;
  core::PcaOptions options;
  if (Status s = ParsePcaConfig(config, &options); !s.ok()) return s;
  if (options.dimension != 3) {
    return Status::InvalidInput("config.dimension: a plan's orientations are three-dimensional")
        .WithField("config.dimension");
  }
  if (!options.nominal) {
    return Status::InvalidInput(
               "config.nominal: the plan needs the nominal sensitivities (one row [x, y, z] per "
               "sensor) to know the sensors it plans for")
        .WithField("config.nominal");
  }
  if (!options.noise_std) {
    return Status::InvalidInput(
               "config.noise_std: the plan needs the σ of one averaged reading (reading units)")
        .WithField("config.noise_std");
  }
  std::vector<std::string> sensors;
  for (Eigen::Index i = 0; i < options.nominal->cols(); ++i) {
    sensors.push_back("s" + std::to_string(i));
  }
  core::PcaInformation info;
  if (Status s = core::ComputePcaInformation(
          DesignSensitivities(options), Directions(protocol.orientations), options.bias, &info);
      !s.ok()) {
    return Status::InvalidInput("config.nominal: the sensors' axes do not span three dimensions")
        .WithField("config.nominal");
  }
  const int p = options.bias == core::BiasModel::kEstimate ? 4 : 3;
  const std::vector<std::string> undetermined = UndeterminedParameters(info, p, sensors);
  json& o = *out;
  o = {{"method", "pca"},
       {"protocol", {{"orientations", OrientationsJson(protocol.orientations, protocol.labels)}}},
       {"undetermined", json::array()},
       {"notes",
        {"σ is the Cramér–Rao bound CalibratePca reports for these orientations at the nominal "
         "sensitivities with the config's noise_std (the σ of one averaged reading: the static "
         "duration and rate enter only through it)"}}};
  if (!undetermined.empty()) {
    std::vector<std::string> missing =
        MissingDirections(protocol.orientations, options.bias == core::BiasModel::kEstimate);
    if (missing.empty()) {
      missing.push_back(std::to_string(protocol.orientations.size()) +
                        " orientations are too few for the parameters: add orientations");
    }
    o["undetermined"].push_back({{"parameters", undetermined}, {"missing", missing}});
    o["uncertainty"] = nullptr;
  } else {
    results::PcaResult result;
    Status s = Predict(options, protocol.orientations, sensors, &result);
    o["uncertainty"] = s.ok() ? results::ToJson(result)["uncertainty"] : json();
    if (!s.ok()) o["notes"].push_back("the calibration of this protocol fails: " + s.message());
  }
  o["suggested"] = Suggest(options, sensors, limits);
  return Status::Ok();
}

}  // namespace calibd::server
