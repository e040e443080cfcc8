// Simulated stationary inertial logs for the `noise` method: per channel, the IEEE 952 / Kalibr
// noise model sampled every τ0 = 1/rate seconds,
//
//   y_k = offset + (N / √τ0) w_k + b_k + Σ_j x_{j,k},
//   b_{k+1} = b_k + K √τ0 v_k,  b_0 = 0                            (rate random walk K)
//   x_{j,k+1} = φ_j x_{j,k} + s_j √(1 − φ_j²) u_{j,k},  φ_j = exp(−τ0/T_j)   (Gauss-Markov)
//
// with w, v, u independent N(0, 1). N is the white noise density (unit/√Hz), K the rate random
// walk (unit/s/√Hz). Bias instability B (unit) is approximated by first-order Gauss-Markov
// processes with correlation times T_j log-spaced over [flicker_min_tau, flicker_max_tau]
// (gauss_markov_per_decade per decade) and equal variances s_j², which together have a 1/f
// spectrum in that band; s_j is chosen so that the exact Allan variance of their sum at the
// band's geometric centre τ_c = √(T_min T_max) is (0.664 B)², the IEEE 952 floor. The curve is
// flat within a few percent over the middle of the band and falls off outside it.
//
// Deterministic per seed on every platform (std::mt19937_64 + Marsaglia's polar method); channel c
// draws from its own stream seeded with (seed, c), so adding channels does not change the others.
#ifndef CALIBD_CORE_NOISE_SIMULATION_H_
#define CALIBD_CORE_NOISE_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace calibd::core {

struct NoiseSimulationChannel {
  std::string name = "g0_x";
  std::string unit = "rad/s";
  double white_noise = 1e-3;    // N >= 0, unit/√Hz
  double random_walk = 0;       // K >= 0, unit/s/√Hz
  double bias_instability = 0;  // B >= 0, unit (0: no Gauss-Markov processes)
  double offset = 0;            // constant added to every sample (e.g. gravity), finite
};

struct NoiseSimulationOptions {
  double rate = 200;                             // samples per second, > 0
  double duration = 3600;                        // seconds, >= 4 samples' worth
  std::vector<NoiseSimulationChannel> channels;  // at least one
  double flicker_min_tau = 1;                    // T_min of the Gauss-Markov band, s, > 0
  double flicker_max_tau = 1000;                 // T_max, s, > flicker_min_tau
  int gauss_markov_per_decade = 2;               // >= 1
  // Timestamp jitter: times are k·τ0 + U(−½, ½)·timestamp_jitter·τ0 (the samples themselves stay
  // uniformly spaced, as with a host clock stamping a sensor's fixed-rate stream). In [0, 1).
  double timestamp_jitter = 0;
  uint64_t seed = 1;

  bool IsValid(std::string* error) const;
};

struct NoiseSimulation {
  double sample_period = 0;        // τ0 = 1/rate
  Eigen::MatrixXf samples;         // n × C, column c is channel c (contiguous floats)
  std::vector<double> times;       // n timestamps, seconds (with the configured jitter)
  std::vector<std::string> names;  // C
  std::vector<std::string> units;  // C
};

// Number of samples of the simulated log: max(4, round(duration · rate)).
int64_t NoiseSimulationSamples(const NoiseSimulationOptions& options);

// Deterministic for options.seed. Precondition: options.IsValid().
NoiseSimulation SimulateNoise(const NoiseSimulationOptions& options);

// The exact Allan variance (expectation of the overlapping estimator) of channel c of the
// simulated process at cluster size m (τ = m τ0): N²/τ + K² τ0 (2m² + 1)/(6m) + the Gauss-Markov
// terms from their autocovariance. Precondition: options.IsValid(), m >= 1.
double SimulatedAllanVariance(const NoiseSimulationOptions& options, int channel, int64_t m);

// The Gauss-Markov correlation times T_j and the common standard deviation s of the bias
// instability approximation of a channel (empty when B = 0).
struct GaussMarkovBank {
  std::vector<double> correlation_time;  // T_j, seconds
  double sigma = 0;                      // s_j (the same for all j), unit
};
GaussMarkovBank BiasInstabilityBank(const NoiseSimulationOptions& options, int channel);

}  // namespace calibd::core

#endif  // CALIBD_CORE_NOISE_SIMULATION_H_
