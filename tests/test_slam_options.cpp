// The SLAM option table (slam_options.hpp): complete, consistent with SlamOptions' defaults, and the
// one source of validation.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <set>
#include <sstream>
#include <string>

#include "lidar2d/slam/slam.hpp"
#include "support/test_support.hpp"

namespace lidar2d::slam {
namespace {

/// The bits of an option's field, to compare values exactly (NaN and -0 included).
std::string fieldBits(const SlamOption& opt, SlamOptions& o) {
  return std::visit(
      [&](auto* ref) {
        const auto v = ref(o);
        std::string bits(sizeof v, '\0');
        std::memcpy(bits.data(), &v, sizeof v);
        return bits;
      },
      opt.ref);
}

TEST(SlamOptionTable, EveryOptionHasANameUnitHelpAndARangeHoldingItsDefault) {
  const SlamOptions defaults;
  std::set<std::string> names, fields;
  for (const SlamOption& opt : slamOptionTable()) {
    SCOPED_TRACE(std::string(opt.field));
    EXPECT_FALSE(opt.name().empty());
    EXPECT_FALSE(opt.unit.empty());
    EXPECT_FALSE(opt.help.empty());
    EXPECT_FALSE(opt.group.empty());
    EXPECT_TRUE(names.insert(opt.name()).second) << "duplicate name";
    EXPECT_TRUE(fields.insert(std::string(opt.field)).second) << "duplicate field";
    EXPECT_EQ(findSlamOption(opt.name()), &opt);
    // Angles and angular rates: radians in the struct, degrees in the name.
    const bool radians = opt.field.ends_with("_rad") || opt.field.find("_rad_per_") != std::string_view::npos;
    EXPECT_EQ(opt.isAngle(), radians);
    EXPECT_EQ(opt.isAngle(), opt.name().ends_with("_deg") || opt.name().find("_deg_per_") != std::string::npos);
    if (opt.isAngle()) {
      EXPECT_EQ(opt.name().find("_rad"), std::string::npos) << opt.name();
    }
    EXPECT_EQ(opt.rangeError(defaults), std::nullopt);
    if (!opt.isFlag()) {
      const double v = std::visit([](auto x) { return static_cast<double>(x); }, opt.get(defaults));
      EXPECT_TRUE(opt.range.contains(v)) << v << " not in " << opt.range.describe();
    } else {
      EXPECT_EQ(opt.range.describe(), "any");
    }
  }
  EXPECT_EQ(findSlamOption("no_such_option"), nullptr);
}

TEST(SlamOptionTable, ListsEveryFieldOfSlamOptions) {
  // Every member with a default in the header's SlamOptions, plus the pose-graph solver's three.
  const std::string header = test::readFile(test::sourceFile("include/lidar2d/slam/slam_options.hpp"));
  const auto begin = header.find("struct SlamOptions {");
  const auto end = header.find("\n};", begin);
  ASSERT_NE(begin, std::string::npos);
  ASSERT_NE(end, std::string::npos);
  std::istringstream body(header.substr(begin, end - begin));
  std::set<std::string> declared{"graph.max_iterations", "graph.threads", "graph.dcs_phi"};
  for (std::string line; std::getline(body, line);) {
    std::istringstream words(line);
    std::string type, name, eq;
    words >> type >> name >> eq;
    if ((type == "bool" || type == "int" || type == "double" || type == "std::size_t") && eq == "=")
      declared.insert(name);
  }
  std::set<std::string> listed;
  for (const SlamOption& opt : slamOptionTable()) listed.insert(std::string(opt.field));
  EXPECT_EQ(declared, listed);
  EXPECT_GT(listed.size(), 50u);
}

TEST(SlamOptionTable, GetThenSetGivesTheSameBits) {
  const SlamOptions defaults;
  for (const SlamOption& opt : slamOptionTable()) {
    SCOPED_TRACE(std::string(opt.field));
    SlamOptions o;
    std::visit([&](auto* ref) { ref(o) = {}; }, opt.ref);  // start from another value
    opt.set(o, opt.get(defaults));
    SlamOptions d = defaults;
    EXPECT_EQ(fieldBits(opt, o), fieldBits(opt, d));
  }
}

TEST(SlamOptionTable, AnglesAreDegreesOutsideTheStruct) {
  const SlamOption* opt = findSlamOption("loop_angular_window_deg");
  ASSERT_NE(opt, nullptr);
  EXPECT_EQ(opt->field, "loop_angular_window_rad");
  SlamOptions o;
  EXPECT_EQ(std::get<double>(opt->get(o)), 15.0);  // not 14.999999999999998
  opt->set(o, 20.0);
  EXPECT_EQ(o.loop_angular_window_rad, 20.0 * kDeg);
  EXPECT_THROW(opt->set(o, 20), Error);  // an int is not this field's type
  EXPECT_EQ(findSlamOption("graph_threads")->field, "graph.threads");
}

TEST(SlamOptionTable, ValidateNamesTheFieldOutOfItsRange) {
  for (const SlamOption& opt : slamOptionTable()) {
    if (opt.isFlag()) continue;
    SCOPED_TRACE(std::string(opt.field));
    // Just outside the lower bound (every option has one).
    ASSERT_TRUE(std::isfinite(opt.range.min));
    SlamOptions o;
    std::visit(
        [&](auto* ref) {
          using T = std::remove_reference_t<decltype(ref(o))>;
          const double scale = opt.isAngle() ? kDeg : 1.0;
          if constexpr (std::is_same_v<T, double>) {
            ref(o) = opt.range.min_open ? opt.range.min * scale : opt.range.min * scale - 0.5;
          } else {
            if (std::is_unsigned_v<T> && opt.range.min < 1.0) return;  // no unsigned value is below 0
            ref(o) = static_cast<T>(opt.range.min - 1.0);
          }
          try {
            o.validate();
            ADD_FAILURE() << "accepted";
          } catch (const Error& e) {
            EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
            EXPECT_EQ(e.where().field, opt.field);
            EXPECT_EQ(e.message(), opt.range.requirement(std::is_integral_v<T>));
          }
          if constexpr (std::is_same_v<T, double>) {
            ref(o) = std::numeric_limits<double>::quiet_NaN();
            EXPECT_THROW(o.validate(), Error);
            ref(o) = std::numeric_limits<double>::infinity();
            EXPECT_THROW(o.validate(), Error);
          }
        },
        opt.ref);
  }
}

TEST(SlamOptionTable, RequirementsReadAsBefore) {
  EXPECT_EQ(OptionRange::above(0).requirement(false), "must be a finite value > 0");
  EXPECT_EQ(OptionRange::atLeast(0).requirement(false), "must be a finite value >= 0");
  EXPECT_EQ(OptionRange::atLeast(3).requirement(true), "must be >= 3");
  EXPECT_EQ(OptionRange::fraction().requirement(false), "must be in (0, 1]");
  EXPECT_EQ(OptionRange::unitInterval().requirement(false), "must be in [0, 1]");
  SlamOptions o;
  o.loop_min_score = 1.5;
  try {
    o.validate();
    FAIL() << "accepted";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "SlamOptions: loop_min_score: must be in (0, 1]");
  }
}

TEST(SlamOptionTable, FormatsValuesToReadBackExactly) {
  EXPECT_EQ(formatOptionValue(true), "true");
  EXPECT_EQ(formatOptionValue(12), "12");
  EXPECT_EQ(formatOptionValue(std::size_t{14}), "14");
  EXPECT_EQ(formatOptionValue(0.05), "0.05");
  EXPECT_EQ(formatOptionValue(30.0), "30");
  EXPECT_EQ(std::stod(formatOptionValue(0.1 + 0.2)), 0.1 + 0.2);
}

}  // namespace
}  // namespace lidar2d::slam
