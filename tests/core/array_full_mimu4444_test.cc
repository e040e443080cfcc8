// The full array model on the public MIMU4444 recordings (Carlsson, Skog, Jaldén 2021; the
// authors' repository hcarlsso/Self-Calibration-Inertial-Sensor-Arrays-BCD.jl, experimental_data/
// calibration/exp_N/data.bin). The recordings are not part of calibd: the test skips when they
// are absent ($CALIBD_MIMU4444_DATA, default /work/data/mimu4444, holding exp_1 ... exp_9).
//
// data.bin: packets of 106 bytes: 0xAA, 0x19, a sequence byte, 0x64, a 4-byte big-endian
// timestamp (64 MHz ticks), 8 IMUs x (accelerometer x y z, gyroscope x y z) as big-endian int16,
// and a big-endian 16-bit sum of the 104 bytes before it. ±16 g (2048 counts/g) and ±2000 °/s
// (16.4 counts per °/s), 62.5 Hz. The IMUs on the underside (2, 4, 6, 8: z = -1 mm) have the
// axis mapping x <-> -y, z -> -z relative to the board frame.
//
// CALIBD_MIMU4444_WEIGHTING=residual runs it with the dynamic samples weighted by their own
// residual level (ArrayFullDynamicWeighting::kResidual) instead of the statics' noise.
// Reports per experiment the fit and its residuals, and across experiments the repeatability of
// the positions and of every triad's parameters next to the reported σ (Cramér-Rao and
// residual-aware).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/array_full.h"
#include "core/array_full_simulation.h"
#include "core/array_simulation.h"
#include "tests/lib/sanitizer.h"

namespace calibd::core {
namespace {

std::string DataDir() {
  const char* env = std::getenv("CALIBD_MIMU4444_DATA");
  return env && *env ? env : "/work/data/mimu4444";
}

// Reads one data.bin into a problem (SI units, board frame); false when unreadable.
bool ReadMimu4444(const std::string& path, ArrayFullProblem* p, int64_t* bad_packets) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  const std::string d((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  constexpr size_t kPacket = 106;
  auto u8 = [&](size_t i) { return static_cast<unsigned>(static_cast<unsigned char>(d[i])); };
  auto i16 = [&](size_t i) { return static_cast<int16_t>((u8(i) << 8) | u8(i + 1)); };
  std::vector<std::array<int16_t, 48>> rows;
  std::vector<double> t;
  *bad_packets = 0;
  uint32_t last_ts = 0;
  double time = 0;
  for (size_t i = 0; i + kPacket <= d.size();) {
    if (u8(i) != 0xAA) {
      ++i;
      continue;
    }
    unsigned sum = 0;
    for (size_t j = 0; j < kPacket - 2; ++j) sum += u8(i + j);
    if ((sum & 0xFFFF) != ((u8(i + 104) << 8) | u8(i + 105))) {
      ++*bad_packets;
      ++i;
      continue;
    }
    const uint32_t ts = (u8(i + 4) << 24) | (u8(i + 5) << 16) | (u8(i + 6) << 8) | u8(i + 7);
    if (!rows.empty()) time += static_cast<uint32_t>(ts - last_ts) / 64e6;
    last_ts = ts;
    std::array<int16_t, 48> row;
    for (int c = 0; c < 48; ++c) row[c] = i16(i + 8 + 2 * c);
    rows.push_back(row);
    t.push_back(time);
    i += kPacket;
  }
  const int64_t N = static_cast<int64_t>(rows.size());
  p->nominal_positions = Mimu4444NominalPositions();
  p->reference = 0;
  p->t = Eigen::Map<Eigen::VectorXd>(t.data(), N);
  p->accel.resize(N, 24);
  p->gyro.resize(N, 24);
  const double a_unit = kStandardGravity / 2048, g_unit = kDegree / 16.4;
  for (int64_t n = 0; n < N; ++n)
    for (int k = 0; k < 8; ++k) {
      Eigen::Vector3d a, g;
      for (int i = 0; i < 3; ++i) {
        a(i) = rows[n][6 * k + i] * a_unit;
        g(i) = rows[n][6 * k + 3 + i] * g_unit;
      }
      if (k % 2 == 1) {  // underside: x <-> -y, z -> -z
        a = Eigen::Vector3d(-a.y(), -a.x(), -a.z());
        g = Eigen::Vector3d(-g.y(), -g.x(), -g.z());
      }
      p->accel.row(n).segment<3>(3 * k) = a.transpose();
      p->gyro.row(n).segment<3>(3 * k) = g.transpose();
    }
  p->names.clear();
  for (int k = 1; k <= 8; ++k) p->names.push_back("IMU" + std::to_string(k));
  return N > 0;
}

struct Stats {
  double mean = 0, std = 0;
};
Stats Spread(const std::vector<double>& v) {
  Stats s;
  for (double x : v) s.mean += x;
  s.mean /= v.size();
  for (double x : v) s.std += (x - s.mean) * (x - s.mean);
  s.std = std::sqrt(s.std / (v.size() - 1));
  return s;
}
double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

TEST(ArrayFullMimu4444, RepeatsAcrossExperimentsWithinTheResidualAwareSigma) {
  if (sanitizer::kAddressSanitizer)
    GTEST_SKIP() << "nine 10-minute recordings take ~30 s of CPU in Release: not under ASan";
  const std::string dir = DataDir();
  std::vector<std::string> files;
  for (int e = 1; e <= 10; ++e) {
    const std::string f = dir + "/exp_" + std::to_string(e) + "/data.bin";
    if (std::filesystem::exists(f)) files.push_back(f);
  }
  if (files.size() < 3)
    GTEST_SKIP() << "MIMU4444 recordings not found under " << dir
                 << " (set CALIBD_MIMU4444_DATA to the folder holding exp_N/data.bin)";
  ArrayFullOptions o;
  o.gyro_saturation = 1995 * kDegree;
  o.threads = 2;
  if (const char* w = std::getenv("CALIBD_MIMU4444_WEIGHTING"); w && std::string(w) == "residual")
    o.dynamic_weighting = ArrayFullDynamicWeighting::kResidual;
  std::vector<ArrayFullResult> results;
  for (const std::string& f : files) {
    ArrayFullProblem p;
    int64_t bad = 0;
    ASSERT_TRUE(ReadMimu4444(f, &p, &bad)) << f;
    ArrayFullResult r;
    const auto t0 = std::chrono::steady_clock::now();
    const Status s = CalibrateArrayFull(p, o, &r);
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_TRUE(s.ok()) << f << ": " << s.message();
    std::printf(
        "%s: %lld samples (%lld bad packets), %lld statics, %lld dynamic (%lld saturated, "
        "%.1f %%), %d iterations (%s), chi2/dof %.1f, static noise %.3f m/s^2 %.3f deg/s, "
        "dynamic rms %.3f m/s^2 (%.0fx) %.2f deg/s (%.0fx), %.1f s\n",
        f.c_str(), static_cast<long long>(p.t.size()), static_cast<long long>(bad),
        static_cast<long long>(r.statics), static_cast<long long>(r.dynamic_samples),
        static_cast<long long>(r.samples_dropped),
        100.0 * r.samples_dropped / (r.dynamic_samples + r.samples_dropped), r.iterations,
        BlockLmTerminationName(r.termination), r.chi2_per_dof, r.static_noise_accel,
        r.static_noise_gyro / kDegree, r.dynamic_rms_accel,
        r.dynamic_rms_accel / r.static_noise_accel, r.dynamic_rms_gyro / kDegree,
        r.dynamic_rms_gyro / r.static_noise_gyro, secs);
    std::printf(
        "  sampling-time offsets: constant per IMU %.3f ms rms (explain %.1f %% of the "
        "gyroscope residual), free per sample %.3f ms rms (explain %.0f %%)\n",
        1e3 * std::sqrt(r.time_offsets.squaredNorm() / 8), 100 * r.time_offset_explained,
        1e3 * r.jitter_rms, 100 * r.jitter_explained);
    EXPECT_TRUE(r.converged) << f;
    EXPECT_GE(r.statics, 18) << f;
    results.push_back(std::move(r));
  }
  // Repeatability of every theta coordinate across experiments against the median reported σ.
  const int P = 27 * 8;
  std::vector<double> ratio_crb, ratio_robust;
  std::vector<double> pos_scatter, pos_crb, pos_robust;
  const char* kKinds[] = {"accel T", "accel bias", "gyro T", "gyro bias", "position"};
  std::vector<std::vector<double>> kind_ratio(5), kind_scatter(5), kind_sigma(5);
  for (int i = 0; i < P; ++i) {
    std::vector<double> v, crb, rob;
    for (const auto& r : results) {
      v.push_back(r.theta(i));
      crb.push_back(std::sqrt(std::max(0.0, r.theta_covariance_crb(i, i))));
      rob.push_back(std::sqrt(std::max(0.0, r.theta_covariance(i, i))));
    }
    const double scatter = Spread(v).std, sc = Median(crb), sr = Median(rob);
    if (sc <= 0) continue;  // gauge
    ratio_crb.push_back(scatter / sc);
    ratio_robust.push_back(scatter / sr);
    const int l = i % 27;
    const int kind = l < 9 ? 0 : l < 12 ? 1 : l < 21 ? 2 : l < 24 ? 3 : 4;
    kind_ratio[kind].push_back(scatter / sr);
    kind_scatter[kind].push_back(scatter);
    kind_sigma[kind].push_back(sr);
    if (kind == 4) {
      pos_scatter.push_back(scatter);
      pos_crb.push_back(sc);
      pos_robust.push_back(sr);
    }
  }
  auto rms = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x * x;
    return std::sqrt(s / v.size());
  };
  std::printf(
      "%zu experiments. positions: scatter rms %.1f um, CRB sigma rms %.2f um, robust "
      "sigma rms %.1f um\n",
      results.size(), 1e6 * rms(pos_scatter), 1e6 * rms(pos_crb), 1e6 * rms(pos_robust));
  for (int k = 0; k < 5; ++k)
    std::printf("  %-10s scatter rms %.3g, robust sigma rms %.3g, median scatter/robust %.2f\n",
                kKinds[k], rms(kind_scatter[k]), rms(kind_sigma[k]), Median(kind_ratio[k]));
  // The reported scale factors (diag of T^-1) of the accelerometers and gyroscopes.
  for (const char* sensor : {"accelerometer", "gyroscope"}) {
    std::vector<double> sc, sd;
    for (int k = 0; k < 8; ++k)
      for (int i = 0; i < 3; ++i) {
        std::vector<double> v, sr;
        for (const auto& r : results) {
          const bool a = sensor[0] == 'a';
          v.push_back(a ? r.report[k].accelerometer.scale(i) : r.report[k].gyroscope.scale(i));
          sr.push_back(a ? r.report_std[k].accelerometer.scale_std(i)
                         : r.report_std[k].gyroscope.scale_std(i));
        }
        sc.push_back(Spread(v).std);
        sd.push_back(Median(sr));
      }
    std::printf("  %s scale factors: scatter rms %.0f ppm, robust sigma rms %.0f ppm\n", sensor,
                1e6 * rms(sc), 1e6 * rms(sd));
  }
  std::printf("median scatter / sigma over all free parameters: CRB %.1f, robust %.2f\n",
              Median(ratio_crb), Median(ratio_robust));
  // Measured (9 experiments): dynamic residuals 21-29x (accelerometers) and 36-45x
  // (gyroscopes) the static noise; positions repeat to 56.5 um rms where the CRB says 1.2 um and
  // the residual-aware σ 75 um. The gyroscope biases scatter ~3x their σ: turn-on bias changes
  // between recordings, which no single recording can predict. Scale factors repeat to
  // 1 366 ppm (accelerometers) and 1 479 ppm (gyroscopes); with CALIBD_MIMU4444_WEIGHTING=residual
  // the accelerometers' to 193 ppm (robust σ 82 ppm), positions 54.9 um (robust σ 54.2 um).
  // Every experiment's residuals exceed the noise, so the residual-aware σ is reported; it
  // predicts the scatter of the positions within a factor 2 where the CRB is far too small.
  for (const auto& r : results) EXPECT_EQ(r.sigma_basis, "sandwich");
  const double pr = rms(pos_scatter) / rms(pos_robust);
  EXPECT_GT(pr, 0.5);
  EXPECT_LT(pr, 2.0);
  if (o.dynamic_weighting == ArrayFullDynamicWeighting::kNoise) {
    EXPECT_GT(rms(pos_scatter) / rms(pos_crb), 5);
  }
}

}  // namespace
}  // namespace calibd::core
