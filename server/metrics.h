// Metrics in the Prometheus text exposition format (version 0.0.4), for GET /api/v1/metrics.
//
// A deliberately small registry: labelled counters and histograms with fixed buckets, rendered on
// demand. Thread-safe: every method may be called from any thread.
#ifndef CALIBD_SERVER_METRICS_H_
#define CALIBD_SERVER_METRICS_H_

#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace calibd::server {

class Metrics {
 public:
  Metrics();

  // One HTTP request finished: route is the path pattern (e.g. "/api/v1/jobs/{id}").
  void ObserveRequest(const std::string& method, const std::string& route, int status,
                      double seconds);
  // A calibration job finished: outcome "succeeded" | "failed" | "retried" | "released".
  void ObserveJob(const std::string& method, const std::string& outcome, double seconds);
  // The acceptance gate judged a stored result: verdict "accepted" | "rejected".
  void ObserveVerdict(const std::string& method, const std::string& verdict);
  // A job failed for good with this reason code (server/failure_reasons.h).
  void ObserveFailure(const std::string& method, const std::string& reason);
  // Bytes of an upload body received (whether or not it was accepted), and its outcome.
  void ObserveUpload(int64_t bytes, int status);

  // The text exposition; `gauges` are appended as given: name -> (labels -> value), e.g.
  // {"calibd_jobs", {{"state=\"queued\"", 3}}}; help texts in `gauge_help`.
  std::string Render(const std::map<std::string, std::map<std::string, double>>& gauges,
                     const std::map<std::string, std::string>& gauge_help) const;

 private:
  struct Histogram {
    std::vector<uint64_t> buckets;  // cumulative at render time; here per-bucket counts
    uint64_t count = 0;
    double sum = 0;
  };
  mutable std::mutex mu_;
  std::vector<double> latency_bounds_, job_bounds_;
  std::map<std::string, uint64_t> requests_;          // labels -> count
  std::map<std::string, Histogram> request_latency_;  // labels -> histogram
  std::map<std::string, Histogram> job_duration_;
  std::map<std::string, uint64_t> jobs_;
  std::map<std::string, uint64_t> verdicts_;
  std::map<std::string, uint64_t> failures_;  // method, reason -> count
  std::map<std::string, uint64_t> uploads_;
  uint64_t upload_bytes_ = 0;
};

// Escapes a label value for the text format (backslash, quote, newline).
std::string EscapeLabelValue(const std::string& value);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_METRICS_H_
