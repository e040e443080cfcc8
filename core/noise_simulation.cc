#include "core/noise_simulation.h"

#include <algorithm>
#include <cmath>
#include <random>

namespace calibd::core {
namespace {

// Reproducible N(0, 1) draws: std::mt19937_64 and Marsaglia's polar method (no sin/cos: about
// twice as fast as Box-Muller; the standard distributions are implementation-defined).
class NormalSource {
 public:
  explicit NormalSource(uint64_t seed) : engine_(seed) {}
  double Uniform() {  // in (0, 1), 53 random bits
    for (;;) {
      const double u = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
      if (u > 0) return u;
    }
  }
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    for (;;) {
      const double u = 2 * Uniform() - 1, v = 2 * Uniform() - 1;
      const double s = u * u + v * v;
      if (s >= 1 || s == 0) continue;
      const double f = std::sqrt(-2 * std::log(s) / s);
      spare_ = v * f;
      has_spare_ = true;
      return u * f;
    }
  }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0;
};

constexpr double kFloorFactor = 0.664;  // IEEE 952: Allan deviation floor = 0.664 B

// Exact Allan variance at cluster size m of a stationary sequence with autocovariance
// r_k = s² φ^k: (V_m − C_m)/m² with V_m = Var(one cluster sum) and C_m = Cov(adjacent sums).
double GaussMarkovAllanVariance(double phi, double variance, int64_t m) {
  double v = static_cast<double>(m);  // in units of s²
  double c = 0;
  double phik = 1;
  for (int64_t k = 1; k <= 2 * m - 1; ++k) {
    phik *= phi;
    if (phik < 1e-300) break;
    if (k < m) v += 2.0 * static_cast<double>(m - k) * phik;
    c += static_cast<double>(std::min(k, 2 * m - k)) * phik;
  }
  return variance * (v - c) / (static_cast<double>(m) * static_cast<double>(m));
}

}  // namespace

bool NoiseSimulationOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  if (!(rate > 0) || !std::isfinite(rate)) return fail("rate must be a finite number > 0");
  if (!(duration > 0) || !std::isfinite(duration)) {
    return fail("duration must be a finite number > 0");
  }
  if (duration * rate > 1e10) return fail("duration * rate must be at most 1e10 samples");
  if (channels.empty()) return fail("at least one channel is needed");
  for (const NoiseSimulationChannel& c : channels) {
    const auto bad = [](double v) { return !(v >= 0) || !std::isfinite(v); };
    if (bad(c.white_noise)) return fail("channel " + c.name + ": white_noise must be >= 0");
    if (bad(c.random_walk)) return fail("channel " + c.name + ": random_walk must be >= 0");
    if (bad(c.bias_instability)) {
      return fail("channel " + c.name + ": bias_instability must be >= 0");
    }
    if (!std::isfinite(c.offset)) return fail("channel " + c.name + ": offset must be finite");
  }
  if (!(flicker_min_tau > 0) || !std::isfinite(flicker_min_tau)) {
    return fail("flicker_min_tau must be a finite number > 0");
  }
  if (!(flicker_max_tau > flicker_min_tau) || !std::isfinite(flicker_max_tau)) {
    return fail("flicker_max_tau must be finite and > flicker_min_tau");
  }
  if (gauss_markov_per_decade < 1 || gauss_markov_per_decade > 20) {
    return fail("gauss_markov_per_decade must be between 1 and 20");
  }
  if (!(timestamp_jitter >= 0 && timestamp_jitter < 1)) {
    return fail("timestamp_jitter must be in [0, 1)");
  }
  return true;
}

int64_t NoiseSimulationSamples(const NoiseSimulationOptions& options) {
  return std::max<int64_t>(4, std::llround(options.duration * options.rate));
}

GaussMarkovBank BiasInstabilityBank(const NoiseSimulationOptions& options, int channel) {
  GaussMarkovBank bank;
  const double b = options.channels[static_cast<size_t>(channel)].bias_instability;
  if (b <= 0) return bank;
  const double decades = std::log10(options.flicker_max_tau / options.flicker_min_tau);
  const int count =
      std::max(1, static_cast<int>(std::ceil(decades * options.gauss_markov_per_decade - 1e-9))) +
      1;
  for (int j = 0; j < count; ++j) {
    bank.correlation_time.push_back(options.flicker_min_tau *
                                    std::pow(10.0, decades * j / (count - 1)));
  }
  const double tau0 = 1 / options.rate;
  const double tau_c = std::sqrt(options.flicker_min_tau * options.flicker_max_tau);
  const int64_t m_c = std::max<int64_t>(1, std::llround(tau_c / tau0));
  double unit_avar = 0;  // Allan variance at τ_c of the bank with s = 1
  for (double t : bank.correlation_time) {
    unit_avar += GaussMarkovAllanVariance(std::exp(-tau0 / t), 1.0, m_c);
  }
  bank.sigma = kFloorFactor * b / std::sqrt(unit_avar);
  return bank;
}

double SimulatedAllanVariance(const NoiseSimulationOptions& options, int channel, int64_t m) {
  const NoiseSimulationChannel& c = options.channels[static_cast<size_t>(channel)];
  const double tau0 = 1 / options.rate;
  const double md = static_cast<double>(m);
  double avar = c.white_noise * c.white_noise / (md * tau0);
  avar += c.random_walk * c.random_walk * tau0 * (2 * md * md + 1) / (6 * md);
  const GaussMarkovBank bank = BiasInstabilityBank(options, channel);
  for (double t : bank.correlation_time) {
    avar += GaussMarkovAllanVariance(std::exp(-tau0 / t), bank.sigma * bank.sigma, m);
  }
  return avar;
}

NoiseSimulation SimulateNoise(const NoiseSimulationOptions& options) {
  NoiseSimulation sim;
  const int64_t n = NoiseSimulationSamples(options);
  const int channels = static_cast<int>(options.channels.size());
  const double tau0 = 1 / options.rate;
  sim.sample_period = tau0;
  sim.samples.resize(n, channels);
  for (int c = 0; c < channels; ++c) {
    const NoiseSimulationChannel& ch = options.channels[static_cast<size_t>(c)];
    sim.names.push_back(ch.name);
    sim.units.push_back(ch.unit);
    NormalSource rng(options.seed * 0x9E3779B97F4A7C15ULL + 0x632BE59BD9B4E019ULL * (c + 1));
    const double white = ch.white_noise / std::sqrt(tau0);
    const double walk = ch.random_walk * std::sqrt(tau0);
    const GaussMarkovBank bank = BiasInstabilityBank(options, c);
    const size_t gm = bank.correlation_time.size();
    std::vector<double> phi(gm), drive(gm), x(gm);
    for (size_t j = 0; j < gm; ++j) {
      phi[j] = std::exp(-tau0 / bank.correlation_time[j]);
      drive[j] = bank.sigma * std::sqrt(1 - phi[j] * phi[j]);
      x[j] = bank.sigma * rng.Normal();  // stationary start
    }
    double b = 0;
    float* out = sim.samples.col(c).data();
    for (int64_t k = 0; k < n; ++k) {
      double y = ch.offset + b;
      if (white > 0) y += white * rng.Normal();
      for (size_t j = 0; j < gm; ++j) {
        y += x[j];
        x[j] = phi[j] * x[j] + drive[j] * rng.Normal();
      }
      if (walk > 0) b += walk * rng.Normal();
      out[k] = static_cast<float>(y);
    }
  }
  sim.times.resize(static_cast<size_t>(n));
  NormalSource clock(options.seed ^ 0xD1B54A32D192ED03ULL);
  for (int64_t k = 0; k < n; ++k) {
    double t = static_cast<double>(k) * tau0;
    if (options.timestamp_jitter > 0)
      t += (clock.Uniform() - 0.5) * options.timestamp_jitter * tau0;
    sim.times[static_cast<size_t>(k)] = t;
  }
  return sim;
}

}  // namespace calibd::core
