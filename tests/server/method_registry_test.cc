// The two registries of methods, server/methods.cc (config, run, gate, exports) and
// web/method_reports.cc (report section, key figures, drift, download links), name the same
// methods in the same order, and the pages offer exactly the formats the server exports.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "server/method.h"
#include "web/method_report.h"

namespace calibd::server {
namespace {

TEST(MethodRegistry, EveryMethodHasAReportInTheSameOrder) {
  const auto& methods = AllMethods();
  const auto& reports = web::AllMethodReports();
  ASSERT_EQ(methods.size(), reports.size());
  for (size_t i = 0; i < methods.size(); ++i) {
    EXPECT_EQ(std::string(methods[i]->name()), reports[i]->method()) << "entry " << i;
    EXPECT_EQ(web::FindMethodReport(methods[i]->name()), reports[i]);
  }
}

TEST(MethodRegistry, PagesLinkExactlyTheFormatsTheServerExports) {
  for (const Method* m : AllMethods()) {
    const web::MethodReport* report = web::FindMethodReport(m->name());
    ASSERT_NE(report, nullptr) << m->name();
    std::vector<std::string> server, page;
    for (const ExportFormat& f : m->ExportFormats()) {
      server.push_back(f.format);
      EXPECT_FALSE(f.label.empty()) << m->name() << " " << f.format;
      EXPECT_FALSE(f.content_type.empty()) << m->name() << " " << f.format;
    }
    for (const auto& d : report->Downloads()) page.push_back(d.format);
    EXPECT_EQ(server, page) << m->name();
  }
}

TEST(MethodRegistry, AFormatAMethodDoesNotHaveIsRefusedNamingIt) {
  for (const Method* m : AllMethods()) {
    std::string out;
    const Status s = m->Export("pdf", nlohmann::json::object(), ExportContext{}, &out);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << m->name();
    EXPECT_EQ(s.field(), "format") << m->name();
    EXPECT_NE(s.message().find("pdf"), std::string::npos) << s.message();
    EXPECT_TRUE(out.empty());
  }
}

}  // namespace
}  // namespace calibd::server
