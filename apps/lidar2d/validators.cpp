// Number checks shared by the subcommands' options.

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <optional>
#include <string>
#include <system_error>

#include <fmt/format.h>

#include "commands.hpp"

namespace lidar2d::cli {
namespace {

// The option's value as a double, or nothing when it does not parse (CLI11 then reports it).
std::optional<double> parse(const std::string& s) {
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

CLI::Validator numberCheck(const char* description, bool (*ok)(double), const char* requirement) {
  return CLI::Validator(
      [ok, requirement](std::string& s) -> std::string {
        const auto v = parse(s);
        if (!v || ok(*v)) return {};
        return fmt::format("must be {}, got {}", requirement, s);
      },
      description);
}

}  // namespace

CLI::Validator positiveNumber() {
  return numberCheck("POSITIVE", [](double v) { return std::isfinite(v) && v > 0; }, "a finite number > 0");
}

CLI::Validator nonNegativeNumber() {
  return numberCheck("NONNEGATIVE", [](double v) { return std::isfinite(v) && v >= 0; }, "a finite number >= 0");
}

void showValuesInWords(CLI::App& app) {
  for (CLI::Option* opt : app.get_options()) {
    const std::string full = opt->get_type_name();
    if (full.empty()) continue;  // flags
    std::string words = full.substr(0, full.find(':'));
    std::string bound;
    for (int i = 0;; ++i) {
      CLI::Validator* v = nullptr;
      try {
        v = opt->get_validator(i);
      } catch (const CLI::OptionNotFound&) {
        break;
      }
      const std::string d = v->get_description();
      v->description("");
      if (d.empty()) continue;
      if (d == "POSITIVE") {
        bound += " > 0";
      } else if (d == "NONNEGATIVE") {
        bound += " >= 0";
      } else if (const auto lo = d.find(" in ["); lo != std::string::npos && d.back() == ']') {
        // CLI::Range: "FLOAT in [0 - 45]".
        std::string range = d.substr(lo + 5, d.size() - lo - 6);
        if (const auto dash = range.find(" - "); dash != std::string::npos) range.replace(dash, 3, "..");
        bound += " in " + range;
      } else if (words == "TEXT") {
        words = d;  // a check that names the value's form: "SX,SY,STH"
      }
    }
    if (words == "FLOAT" || words == "DOUBLE") {
      words = "NUMBER";
    } else if (words == "INT" || words == "UINT") {
      words = "INTEGER";
    } else if (words == "TEXT") {
      std::string help = opt->get_description();
      std::transform(help.begin(), help.end(), help.begin(), [](unsigned char c) { return std::tolower(c); });
      words = "NAME";
      for (const char* path : {"file", "folder", "log", "map", "prefix", "path", "output", "directory", "database",
                               "trajectory", "image"})
        if (help.find(path) != std::string::npos) words = "PATH";
    }
    opt->type_name(words + bound);
  }
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) showValuesInWords(*sub);
}

void requireFiniteNumbers(CLI::App& app) {
  const CLI::Validator finite = numberCheck("", [](double v) { return std::isfinite(v); }, "a finite number");
  for (CLI::Option* opt : app.get_options())
    if (opt->get_type_name().rfind("FLOAT", 0) == 0) opt->check(finite);
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) requireFiniteNumbers(*sub);
}

}  // namespace lidar2d::cli
