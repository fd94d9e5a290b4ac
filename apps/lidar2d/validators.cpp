// Number checks shared by the subcommands' options.

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

void requireFiniteNumbers(CLI::App& app) {
  const CLI::Validator finite = numberCheck("", [](double v) { return std::isfinite(v); }, "a finite number");
  for (CLI::Option* opt : app.get_options())
    if (opt->get_type_name().rfind("FLOAT", 0) == 0) opt->check(finite);
  for (CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) requireFiniteNumbers(*sub);
}

}  // namespace lidar2d::cli
