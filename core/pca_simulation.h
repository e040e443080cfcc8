// The paper's Section IV simulation set-up for the `pca` method (four gyroscope triads of
// a_model, axes perturbed, random orientations, Gaussian noise), deterministic per seed on every
// platform: std::mt19937_64 with our own uniform and Box-Muller normal sampling.
#ifndef CALIBD_CORE_PCA_SIMULATION_H_
#define CALIBD_CORE_PCA_SIMULATION_H_

#include <Eigen/Core>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace calibd::core {

// Reproducible random numbers (the standard distributions are implementation-defined).
class PcaRandom {
 public:
  explicit PcaRandom(uint64_t seed) : engine_(seed) {}
  double Uniform();                                            // in (0, 1), 53 random bits
  double Normal();                                             // N(0, 1), Box-Muller
  Eigen::MatrixXd NormalMatrix(int rows, int cols);            // i.i.d. N(0, 1), column by column
  Eigen::VectorXd UnitVector(int d);                           // uniform on the unit sphere of R^d
  Eigen::MatrixXd SphereColumns(int d, int n, double radius);  // n uniform directions × radius

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0;
};

// The paper's a_model (3×12, four triads; columns = sensors).
Eigen::MatrixXd PcaModelSensitivities();

struct PcaSimulationOptions {
  int positions = 100;              // n >= 1 random orientations
  double noise_std = 0.01;          // σ of each averaged reading, >= 0
  double axis_perturbation = 0.01;  // σ of the Gaussian perturbation of each a_model column, >= 0
  double magnitude = 1.0;           // c > 0
  double bias_std = 0.0;            // >= 0; > 0 adds a N(0, bias_std²) bias to each sensor
  uint64_t seed = 1;

  bool IsValid(std::string* error) const;
};

struct PcaSimulation {
  Eigen::MatrixXd a_true;                 // 3×12
  Eigen::MatrixXd a_model;                // 3×12
  Eigen::MatrixXd v;                      // 3×n, |v_j| = magnitude
  Eigen::VectorXd b;                      // 12 biases (zeros unless bias_std > 0)
  Eigen::MatrixXd m;                      // 12×n readings a_trueᵀ v + b + noise
  std::vector<std::string> sensor_names;  // g0_x, g0_y, g0_z, g1_x, ..., g3_z
};

// Deterministic for options.seed. Precondition: options.IsValid().
PcaSimulation SimulatePca(const PcaSimulationOptions& options);

}  // namespace calibd::core

#endif  // CALIBD_CORE_PCA_SIMULATION_H_
