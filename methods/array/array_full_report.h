// The job-page sections of an `array` result with `model: full` (SPEC §7, issue #18): every
// triad's accelerometer and gyroscope gains, misalignment angles and biases with their 1σ, the
// residuals per triad in the statics and in motion against the static noise, and what the full
// model changed compared with the positions-only fit it starts from.
//
// Input: the typed result (methods/array/array_result.h: parameters.imus, uncertainty.imus,
// diagnostics.residual_rms.imus, diagnostics.static_noise, diagnostics.changed_from_positions_only,
// diagnostics.gyro_unit) and its verdict.limits (the acceptance limits it was judged against;
// values beyond them are marked, class "beyond", with the limit in the cell's title; a result not
// yet judged marks nothing). Undefined numbers (null) show as "–". Every name is escaped.
//
// σ shown: the primary (uncertainty.basis: the residual-aware sandwich when the residuals exceed
// the noise model, else the Cramér–Rao bound; the bound itself is in uncertainty.imus[].crb);
// limits and the shift in σ are judged against it.
//
// Layout (32 triads stay readable): one table per sensor kind, one row per triad, column groups
// gain − 1 (%), axis misalignment (mrad), bias (reading units), each value with its σ in small
// print beside it; the full misalignment entries in a collapsed <details> table; a bar chart per
// sensor kind of the residual RMS per triad (statics and motion, log scale, static noise as a
// reference line) with the triads that stand out named in words; a table and a bar chart of the
// position shift from the positions-only fit, in µm and in units of σ.
//
// Pure functions, thread-safe.
#ifndef CALIBD_WEB_ARRAY_FULL_REPORT_H_
#define CALIBD_WEB_ARRAY_FULL_REPORT_H_

#include <nlohmann/json.hpp>
#include <string>

#include "methods/array/array_result.h"

namespace calibd::web {

// What the σ of an array result is (HTML, safe), both models, from uncertainty.basis and
// chi2_per_dof: "residual-aware sandwich (...)", "Cramér–Rao bound (...)", or, for a result
// stored by an earlier calibd, "Cramér–Rao σ only (stored by an earlier calibd)".
std::string ArraySigmaBasisText(const results::ArrayUncertainty& u);

// The sections (HTML, safe): section#triads (table.table-array-full-accelerometer,
// table.table-array-full-gyroscope, table.table-array-full-misalignment), section#triad-residuals
// (svg.plot-array-full-residuals-accelerometer / -gyroscope), section#full-vs-positions
// (table.table-array-full-change, svg.plot-array-full-position-change). Never throws. A result
// that is not a usable one of model full gets a "not available" line.
std::string ArrayFullSections(const results::ArrayResult& result);
// The same of a result document (results::FromJson once; a document that does not read gets the
// "not available" line with the reader's message).
std::string ArrayFullSections(const nlohmann::json& result);

}  // namespace calibd::web

#endif  // CALIBD_WEB_ARRAY_FULL_REPORT_H_
