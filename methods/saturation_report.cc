#include "methods/saturation_report.h"

#include <cmath>
#include <cstdio>

namespace calibd::server {
namespace {

template <class M>
Status FindImpl(const M& columns, const std::vector<std::string>& names,
                const core::SaturationOptions& options, std::vector<core::ChannelSaturation>* out) {
  if (columns.cols() != 3 * static_cast<Eigen::Index>(names.size())) {
    return Status::Internal("saturation: " + std::to_string(columns.cols()) + " columns for " +
                            std::to_string(names.size()) + " triads");
  }
  for (size_t k = 0; k < names.size(); ++k) {
    std::array<core::ChannelSaturation, 3> triad;
    Status s = core::FindTriadSaturation(columns.middleCols(3 * static_cast<Eigen::Index>(k), 3),
                                         names[k], options, &triad);
    if (!s.ok()) return s;
    for (auto& c : triad) out->push_back(std::move(c));
  }
  return Status::Ok();
}

template <class M>
int64_t PinnedRowsImpl(const M& columns, const std::vector<core::ChannelSaturation>& channels) {
  int64_t rows = 0;
  const Eigen::Index n = columns.cols() == static_cast<Eigen::Index>(channels.size())
                             ? columns.rows()
                             : 0;  // a mismatch counts nothing
  for (Eigen::Index i = 0; i < n; ++i) {
    for (size_t c = 0; c < channels.size(); ++c) {
      const double v = static_cast<double>(columns(i, static_cast<Eigen::Index>(c)));
      if (v <= channels[c].low || v >= channels[c].high) {
        ++rows;
        break;
      }
    }
  }
  return rows;
}

std::string Level(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%+.6g", v);
  return buf;
}

}  // namespace

Status FindSaturation(const Eigen::Ref<const Eigen::MatrixXd>& columns,
                      const std::vector<std::string>& names, const core::SaturationOptions& options,
                      std::vector<core::ChannelSaturation>* out) {
  return FindImpl(columns, names, options, out);
}

Status FindSaturation(const Eigen::Ref<const Eigen::MatrixXf>& columns,
                      const std::vector<std::string>& names, const core::SaturationOptions& options,
                      std::vector<core::ChannelSaturation>* out) {
  return FindImpl(columns, names, options, out);
}

int64_t PinnedRows(const Eigen::Ref<const Eigen::MatrixXd>& columns,
                   const std::vector<core::ChannelSaturation>& channels) {
  return PinnedRowsImpl(columns, channels);
}

int64_t PinnedRows(const Eigen::Ref<const Eigen::MatrixXf>& columns,
                   const std::vector<core::ChannelSaturation>& channels) {
  return PinnedRowsImpl(columns, channels);
}

bool AnyPinned(const std::vector<core::ChannelSaturation>& channels) {
  for (const auto& c : channels) {
    if (c.pinned() > 0) return true;
  }
  return false;
}

void AddSaturationChannels(const std::vector<core::ChannelSaturation>& channels, double scale,
                           const std::string& unit, results::SaturationDiagnostics* out) {
  for (const core::ChannelSaturation& c : channels) {
    if (c.pinned() == 0) continue;
    out->channels.push_back(
        {c.name, c.source, unit, c.low * scale, c.high * scale, c.pinned_low, c.pinned_high});
  }
}

std::string PinnedList(const results::SaturationDiagnostics& s, size_t max) {
  std::string out;
  for (size_t i = 0; i < s.channels.size() && i < max; ++i) {
    const results::SaturationChannel& c = s.channels[i];
    std::string at;
    if (c.pinned_low > 0) at += Level(c.low);
    if (c.pinned_high > 0) at += (at.empty() ? "" : "/") + Level(c.high);
    out += (i ? ", " : "") + c.name + ": " + std::to_string(c.pinned_low + c.pinned_high) +
           " samples pinned at " + at + " " + c.unit;
  }
  if (s.channels.size() > max) {
    out += " (and " + std::to_string(s.channels.size() - max) +
           " more channels: diagnostics.saturation)";
  }
  return out;
}

}  // namespace calibd::server
