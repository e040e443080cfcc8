#include "server/metrics.h"

#include <algorithm>
#include <cstdio>
#include <sstream>

namespace calibd::server {

namespace {

std::string FormatDouble(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

void AddToHistogram(const std::vector<double>& bounds, double value, uint64_t* buckets,
                    uint64_t* count, double* sum) {
  const size_t i = std::lower_bound(bounds.begin(), bounds.end(), value) - bounds.begin();
  ++buckets[i];  // bucket i: value <= bounds[i]; the last one is +Inf
  ++*count;
  *sum += value;
}

}  // namespace

std::string EscapeLabelValue(const std::string& value) {
  std::string out;
  out.reserve(value.size());
  for (char c : value) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '"')
      out += "\\\"";
    else if (c == '\n')
      out += "\\n";
    else
      out += c;
  }
  return out;
}

Metrics::Metrics()
    : latency_bounds_{0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1,
                      0.25,   0.5,   1,      2.5,   5,    10,    30},
      job_bounds_{0.001, 0.01, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 300} {}

void Metrics::ObserveRequest(const std::string& method, const std::string& route, int status,
                             double seconds) {
  const std::string route_labels =
      "method=\"" + EscapeLabelValue(method) + "\",route=\"" + EscapeLabelValue(route) + "\"";
  std::lock_guard<std::mutex> lock(mu_);
  ++requests_[route_labels + ",status=\"" + std::to_string(status) + "\""];
  Histogram& h = request_latency_[route_labels];
  if (h.buckets.empty()) h.buckets.assign(latency_bounds_.size() + 1, 0);
  AddToHistogram(latency_bounds_, seconds, h.buckets.data(), &h.count, &h.sum);
}

void Metrics::ObserveJob(const std::string& method, const std::string& outcome, double seconds) {
  const std::string labels = "method=\"" + EscapeLabelValue(method) + "\"";
  std::lock_guard<std::mutex> lock(mu_);
  ++jobs_[labels + ",outcome=\"" + EscapeLabelValue(outcome) + "\""];
  Histogram& h = job_duration_[labels];
  if (h.buckets.empty()) h.buckets.assign(job_bounds_.size() + 1, 0);
  AddToHistogram(job_bounds_, seconds, h.buckets.data(), &h.count, &h.sum);
}

void Metrics::ObserveVerdict(const std::string& method, const std::string& verdict) {
  std::lock_guard<std::mutex> lock(mu_);
  ++verdicts_["method=\"" + EscapeLabelValue(method) + "\",verdict=\"" + EscapeLabelValue(verdict) +
              "\""];
}

void Metrics::ObserveFailure(const std::string& method, const std::string& reason) {
  std::lock_guard<std::mutex> lock(mu_);
  ++failures_["method=\"" + EscapeLabelValue(method) + "\",reason=\"" + EscapeLabelValue(reason) +
              "\""];
}

void Metrics::ObserveUpload(int64_t bytes, int status) {
  std::lock_guard<std::mutex> lock(mu_);
  upload_bytes_ += static_cast<uint64_t>(std::max<int64_t>(bytes, 0));
  ++uploads_["status=\"" + std::to_string(status) + "\""];
}

std::string Metrics::Render(const std::map<std::string, std::map<std::string, double>>& gauges,
                            const std::map<std::string, std::string>& gauge_help) const {
  std::ostringstream out;
  auto histograms = [&out](const char* name, const char* help, const std::vector<double>& bounds,
                           const std::map<std::string, Histogram>& series) {
    out << "# HELP " << name << " " << help << "\n# TYPE " << name << " histogram\n";
    for (const auto& [labels, h] : series) {
      uint64_t cumulative = 0;
      for (size_t i = 0; i < h.buckets.size(); ++i) {
        cumulative += h.buckets[i];
        const std::string le = i < bounds.size() ? FormatDouble(bounds[i]) : "+Inf";
        out << name << "_bucket{" << labels << ",le=\"" << le << "\"} " << cumulative << "\n";
      }
      out << name << "_sum{" << labels << "} " << FormatDouble(h.sum) << "\n";
      out << name << "_count{" << labels << "} " << h.count << "\n";
    }
  };
  auto counters = [&out](const char* name, const char* help,
                         const std::map<std::string, uint64_t>& series) {
    out << "# HELP " << name << " " << help << "\n# TYPE " << name << " counter\n";
    for (const auto& [labels, v] : series) out << name << "{" << labels << "} " << v << "\n";
  };
  std::lock_guard<std::mutex> lock(mu_);
  counters("calibd_http_requests_total", "HTTP requests by method, route and status.", requests_);
  histograms("calibd_http_request_duration_seconds", "HTTP request latency.", latency_bounds_,
             request_latency_);
  counters("calibd_jobs_finished_total", "Calibration job runs by method and outcome.", jobs_);
  counters("calibd_verdicts_total",
           "Results judged by the acceptance gate, by method and verdict (rejected results are "
           "never served).",
           verdicts_);
  counters("calibd_job_failures_total",
           "Jobs that failed for good, by method and failure reason (README \"Failure reasons\").",
           failures_);
  histograms("calibd_job_duration_seconds", "Calibration job run time by method.", job_bounds_,
             job_duration_);
  counters("calibd_uploads_total", "Recording uploads by HTTP status.", uploads_);
  out << "# HELP calibd_upload_bytes_total Bytes of upload bodies received.\n"
      << "# TYPE calibd_upload_bytes_total counter\ncalibd_upload_bytes_total " << upload_bytes_
      << "\n";
  for (const auto& [name, series] : gauges) {
    auto help = gauge_help.find(name);
    out << "# HELP " << name << " " << (help == gauge_help.end() ? name : help->second) << "\n"
        << "# TYPE " << name << " gauge\n";
    for (const auto& [labels, v] : series) {
      out << name;
      if (!labels.empty()) out << "{" << labels << "}";
      out << " " << FormatDouble(v) << "\n";
    }
  }
  return out.str();
}

}  // namespace calibd::server
