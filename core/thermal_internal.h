// Stages of core/thermal.h shared by core/thermal.cc and core/thermal_lag.cc (not a public API:
// only those two files include it). Pure numerics, thread-compatible.
#ifndef CALIBD_CORE_THERMAL_INTERNAL_H_
#define CALIBD_CORE_THERMAL_INTERNAL_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/thermal.h"

namespace calibd::core::thermal_internal {

// The samples [first, last] of one averaging window (stage 1).
struct WindowRange {
  int64_t first = 0, last = 0;
};

// A window's temperature, its rate (least-squares slope over the window) and phase from temp.
void SetWindowTemperature(const Eigen::VectorXd& t, const Eigen::VectorXd& temp,
                          const WindowRange& range, double min_rate, ThermalWindow* w);

// The windows of one phase (0: all, in window order) as fit inputs for channel c (0..5); groups
// re-indexed densely in order of first appearance. `gravity_of_orientation` non-empty (an
// accelerometer channel with a scale curve): each window's gravity component along the axis.
struct ChannelData {
  Eigen::VectorXd x, y, sigma;  // x = T − t_ref (°C), y SI, σ of y
  Eigen::VectorXd gravity;      // G_w, SI; empty without a scale curve
  std::vector<int> group;
  std::vector<int> group_of_orientation;  // orientation -> dense group, −1 absent
  int64_t samples = 0;                    // the samples behind the selected windows
  int groups = 0;
  double t_lo = 0, t_hi = 0;
};
ChannelData SelectWindows(const std::vector<ThermalWindow>& windows, int c, int phase, double t_ref,
                          int orientations, const std::vector<double>& gravity_of_orientation = {});

// Stage 5. The sensing element's temperature: the reading through dT_s/dt = (T_r − T_s)/τ
// (τ = 0: the reading itself), per step with the mean of the step's two readings, from a state
// started on a least-squares line through the reading's first `start` seconds.
Eigen::VectorXd LaggedTemperature(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                                  double tau, double start);
// The mean of LaggedTemperature over each range (ranges in time order, not overlapping), without
// storing it.
Eigen::VectorXd LaggedWindowTemperatures(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                                         double tau, double start,
                                         const std::vector<WindowRange>& ranges);

// kNotDeterminable unless the windows (temperatures of the reading) heat and cool over a common
// range of at least a quarter of the range, with 3 windows of each phase inside it.
Status CheckLagDeterminable(const std::vector<ThermalWindow>& windows, const std::string& imu);

// The τ of the profile minimum (imu.windows: channel means and orientations; their temperatures
// are not used); fills imu.lag_grid / lag_profile. `scale` as for FitThermalPolynomial.
Status EstimateLag(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                   const std::vector<WindowRange>& ranges, const ThermalOptions& options,
                   double scale, ThermalImuResult* imu, double* tau);

// After the channel fits at τ = *imu.lag: σ_τ (primary and crb) and each channel's covariance
// widened by τ's uncertainty (stage 5). kNotDeterminable when the log carries no information on τ.
Status AddLagUncertainty(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                         const std::vector<WindowRange>& ranges, const ThermalOptions& options,
                         ThermalImuResult* imu);

}  // namespace calibd::core::thermal_internal

#endif  // CALIBD_CORE_THERMAL_INTERNAL_H_
