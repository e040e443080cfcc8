// The one registry of methods (methods/registry.h): each descriptor pairs a method (config, run,
// gate, exports) with its own report (section, key figures, drift), names are unique and found,
// and the pages offer exactly the formats the server exports.
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

#include "methods/method.h"
#include "methods/registry.h"
#include "web/method_report.h"
#include "web/pages.h"

namespace calibd::server {
namespace {

TEST(MethodRegistry, EachDescriptorPairsAMethodWithItsOwnReport) {
  const auto& descriptors = AllMethodDescriptors();
  const auto& methods = AllMethods();
  ASSERT_EQ(descriptors.size(), methods.size());
  std::set<std::string> names;
  for (size_t i = 0; i < descriptors.size(); ++i) {
    const MethodDescriptor& d = descriptors[i];
    ASSERT_NE(d.method, nullptr) << "entry " << i;
    ASSERT_NE(d.report, nullptr) << "entry " << i;
    EXPECT_EQ(std::string(d.method->name()), d.report->method()) << "entry " << i;
    EXPECT_EQ(methods[i], d.method) << "entry " << i;
    EXPECT_EQ(FindMethod(d.method->name()), d.method);
    EXPECT_EQ(web::FindMethodReport(d.method->name()), d.report);
    EXPECT_TRUE(names.insert(d.method->name()).second) << "twice: " << d.method->name();
  }
  EXPECT_EQ(FindMethod("no-such-method"), nullptr);
  EXPECT_EQ(web::FindMethodReport("no-such-method"), nullptr);
}

TEST(MethodRegistry, PagesLinkExactlyTheFormatsTheServerExports) {
  for (const Method* m : AllMethods()) {
    const std::string links = web::internal::ExportLinks("/c?format=", m->name());
    std::string expected = "<a href=\"/c?format=json\">JSON</a>";
    for (const ExportFormat& f : m->ExportFormats()) {
      EXPECT_FALSE(f.label.empty()) << m->name() << " " << f.format;
      EXPECT_FALSE(f.content_type.empty()) << m->name() << " " << f.format;
      expected += " \xC2\xB7 <a href=\"/c?format=" + f.format + "\">" + f.label + "</a>";
    }
    EXPECT_EQ(links, expected) << m->name();
  }
  EXPECT_EQ(web::internal::ExportLinks("/c?format=", "no-such-method"),
            "<a href=\"/c?format=json\">JSON</a>");
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
