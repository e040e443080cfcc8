// The mag result JSON (methods/mag/mag_method.h) of the core results.
#include <algorithm>
#include <cmath>

#include "methods/mag/mag_method.h"

namespace calibd::server {

using nlohmann::json;

namespace {

json Num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json Vec(const Eigen::VectorXd& v) {
  json out = json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) out.push_back(Num(v(i)));
  return out;
}

json Mat(const Eigen::MatrixXd& m) {
  json out = json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) out.push_back(Vec(m.row(r).transpose()));
  return out;
}

// The uncertainty entry's keys (without "name") of one set of σ; alignment and dip null when
// the alignment was not estimated.
json StdKeys(const core::MagStd& s, bool aligned) {
  return {{"hard_iron_std", Vec(s.hard_iron)},
          {"soft_iron_std", Mat(s.soft_iron)},
          {"alignment_std", aligned ? Vec(s.alignment) : json(nullptr)},
          {"dip_std", aligned ? Num(s.dip) : json(nullptr)}};
}

// Up to kMagPlotPoints samples, evenly spaced: time, raw and calibrated readings, |m| − F and
// whether the sample lies in a disturbed span.
json PlotData(const MagRun& run) {
  const core::MagProblem& p = *run.problem;
  const core::MagResult& r = run.result;
  const Eigen::Index n = p.y.cols();
  const Eigen::Index step = std::max<Eigen::Index>(1, (n + kMagPlotPoints - 1) / kMagPlotPoints);
  json t = json::array(), raw = json::array({json::array(), json::array(), json::array()});
  json cal = raw, residual = json::array(), disturbed = json::array();
  for (Eigen::Index i = 0; i < n; i += step) {
    const Eigen::Vector3d m = r.soft_iron * (p.y.col(i) - r.hard_iron);
    t.push_back(p.t(i));
    for (int a = 0; a < 3; ++a) {
      raw[a].push_back(p.y(a, i));
      cal[a].push_back(m(a));
    }
    residual.push_back(m.norm() - r.field);
    bool in_span = false;
    for (const core::MagSpan& s : r.disturbed_spans)
      in_span |= p.t(i) >= s.start && p.t(i) <= s.end;
    disturbed.push_back(in_span ? 1 : 0);
  }
  return {{"t", t},
          {"raw", raw},
          {"calibrated", cal},
          {"residual", residual},
          {"disturbed", disturbed},
          {"every", step}};
}

}  // namespace

json MagDiagnostics(const MagRun& run, const std::string& unit_text) {
  const core::MagResult& r = run.result;
  json spans = json::array();
  for (const core::MagSpan& s : r.disturbed_spans) {
    spans.push_back({{"start", s.start},
                     {"end", s.end},
                     {"samples", s.samples},
                     {"max_residual", Num(s.max_residual)}});
  }
  json blocking = json::array();
  for (const core::MagBlockingStep& b : r.blocking) {
    blocking.push_back({{"seconds", b.seconds}, {"batches", b.batches}, {"ratio", Num(b.ratio)}});
  }
  const core::MagCoverage& c = r.coverage;
  const double chi2 =
      r.residual_rms_clean * r.residual_rms_clean / (run.sample_noise_std * run.sample_noise_std);
  json out = {
      {"name", run.name},
      {"samples", r.samples},
      {"disturbed_samples", r.disturbed_samples},
      {"disturbed_fraction",
       r.samples > 0 ? static_cast<double>(r.disturbed_samples) / r.samples : 0.0},
      {"disturbed_spans", spans},
      {"noise_std", Num(r.noise_std)},
      {"sample_noise_std", Num(run.sample_noise_std)},
      {"chi2", Num(chi2)},
      {"residual_rms_before", Num(r.residual_rms_before)},
      {"residual_rms_after", Num(r.residual_rms_after)},
      {"residual_rms_clean", Num(r.residual_rms_clean)},
      {"sandwich_ratio", Num(r.sandwich_ratio)},
      {"blocking", blocking},
      {"plateau", r.plateau},
      // core/mag.h step 3c: the hard iron's random walk where the blocking found no plateau.
      {"wander",
       {{"included", r.wander_included},
        {"rate", r.wander_included ? Vec(r.wander_rate) : json(nullptr)},
        {"rate_unit", unit_text + "/sqrt(s)"},
        {"segments", r.wander_segments},
        {"segment_seconds", Num(r.wander_segment_seconds)}}},
      {"iterations", r.iterations},
      {"statics", run.statics},
      {"accelerometer", run.accelerometer.empty() ? json(nullptr) : json(run.accelerometer)},
      {"alignment_note", r.alignment_note},
      {"coverage",
       {{"eigenvalues", Vec(c.eigenvalues)},
        {"least_covered_direction", Vec(c.least_covered_direction)},
        {"missing", c.missing},
        {"sufficient", c.sufficient},
        {"verdict", c.verdict}}}};
  if (run.problem != nullptr && run.problem->y.cols() > 0) out["plot"] = PlotData(run);
  return out;
}

json MagResultToJson(const std::vector<MagRun>& runs, const std::string& unit_text,
                     double microtesla_per_unit, double field) {
  json params = json::array(), unc = json::array(), diag = json::array(), warnings = json::array();
  bool sandwich = false;
  for (const MagRun& run : runs) {
    const core::MagResult& r = run.result;
    const bool aligned = r.alignment.has_value();
    params.push_back({{"name", run.name},
                      {"hard_iron", Vec(r.hard_iron)},
                      {"soft_iron", Mat(r.soft_iron)},
                      {"soft_iron_symmetric", Mat(r.soft_iron_symmetric)},
                      {"alignment", aligned ? Mat(*r.alignment) : json(nullptr)},
                      {"dip", r.dip ? Num(*r.dip) : json(nullptr)},
                      {"field", field > 0 ? json(field) : json(nullptr)},
                      {"field_estimate", Num(r.field_estimate)},
                      {"mag_unit", unit_text},
                      {"microtesla_per_unit", microtesla_per_unit},
                      {"device_id", run.device_id >= 0 ? json(run.device_id) : json(nullptr)},
                      {"device_id_source",
                       run.device_id_source.empty() ? json(nullptr) : json(run.device_id_source)}});
    json u = StdKeys(r.std, aligned);
    u["name"] = run.name;
    u["crb"] = StdKeys(r.crb, aligned);
    unc.push_back(u);
    diag.push_back(MagDiagnostics(run, unit_text));
    sandwich |= r.basis == "sandwich";
    for (const auto* list : {&run.warnings, &r.warnings}) {
      for (const std::string& w : *list)
        warnings.push_back(runs.size() > 1 ? run.name + ": " + w : w);
    }
    if (!aligned) {
      warnings.push_back(run.name + ": alignment to the accelerometer not estimated (" +
                         r.alignment_note + "): soft_iron is the symmetric P");
    }
  }
  return {{"method", "mag"},
          {"model",
           "per magnetometer, m = S (y - h): y the reading (mag_unit), h the hard iron (reading "
           "units), S = R P the soft iron (P symmetric, R the rotation to the accelerometer frame "
           "where estimated), |m| = field (uT; 1 when no field was given)"},
          {"parameters", {{"mags", params}}},
          {"uncertainty",
           {{"basis", sandwich ? "sandwich" : "crb"}, {"chi2_per_dof", nullptr}, {"mags", unc}}},
          {"diagnostics", {{"mags", diag}}},
          {"warnings", warnings}};
}

}  // namespace calibd::server
