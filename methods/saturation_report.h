// The adapters' side of saturation found in the data (core/saturation.h): search every triad of
// a kind, turn the levels into the one limit pair a method takes, and report them (a warning and
// diagnostics.saturation, results/saturation.h).
#ifndef CALIBD_SERVER_SATURATION_REPORT_H_
#define CALIBD_SERVER_SATURATION_REPORT_H_

#include <Eigen/Core>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/saturation.h"
#include "results/saturation.h"

namespace calibd::server {

// The channels of one sensor kind of a log: `columns` N×3K (reading units), triad k named
// names[k] (its channels names[k] + "_x", ...). `options` carries a configured limit (then the
// data are not searched) and the stop token. Appends every channel to *out.
Status FindSaturation(const Eigen::Ref<const Eigen::MatrixXd>& columns,
                      const std::vector<std::string>& names, const core::SaturationOptions& options,
                      std::vector<core::ChannelSaturation>* out);
Status FindSaturation(const Eigen::Ref<const Eigen::MatrixXf>& columns,
                      const std::vector<std::string>& names, const core::SaturationOptions& options,
                      std::vector<core::ChannelSaturation>* out);

// Rows of `columns` with any channel at or beyond its level (channels in the order found).
int64_t PinnedRows(const Eigen::Ref<const Eigen::MatrixXd>& columns,
                   const std::vector<core::ChannelSaturation>& channels);
int64_t PinnedRows(const Eigen::Ref<const Eigen::MatrixXf>& columns,
                   const std::vector<core::ChannelSaturation>& channels);

// Whether any channel has a pinned sample.
bool AnyPinned(const std::vector<core::ChannelSaturation>& channels);

// The channels with pinned samples, their levels times `scale` in `unit`, appended to *out.
void AddSaturationChannels(const std::vector<core::ChannelSaturation>& channels, double scale,
                           const std::string& unit, results::SaturationDiagnostics* out);

// "g3_x: 386 samples pinned at -1998/+1998 deg/s, g3_y: ... (and 20 more channels)" for the
// channels with pinned samples (at most `max` named).
std::string PinnedList(const results::SaturationDiagnostics& s, size_t max = 4);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_SATURATION_REPORT_H_
