#include "lidar2d/slam/slam_options.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>

#include "lidar2d/core/error.hpp"

namespace lidar2d::slam {
namespace {

/// The shortest decimal number of degrees d with d * kDeg == rad (the conversion `set` makes), so
/// that printed angles read back to exactly the same options; rad / kDeg when there is none.
double degreesOf(double rad) {
  const double deg = rad / kDeg;
  if (!std::isfinite(deg)) return deg;
  for (int digits = 1; digits <= 17; ++digits) {
    const double d = std::strtod(fmt::format("{:.{}g}", deg, digits).c_str(), nullptr);
    if (d * kDeg == rad) return d;
  }
  return deg;
}

}  // namespace

std::string SlamOption::name() const {
  std::string n(field);
  for (char& c : n)
    if (c == '.') c = '_';
  // The radians of an angle (or of an angular rate, "_rad_per_s") are degrees in the name.
  if (isAngle())
    for (std::size_t at = n.find("_rad"); at != std::string::npos; at = n.find("_rad", at + 1))
      if (at + 4 == n.size() || n[at + 4] == '_') {
        n.replace(at, 4, "_deg");
        break;
      }
  return n;
}

bool OptionRange::contains(double v) const {
  if (std::isnan(v)) return false;
  if (min_open ? !(v > min) : !(v >= min)) return false;
  if (max_open ? !(v < max) : !(v <= max)) return false;
  return true;
}

std::string OptionRange::requirement(bool integer) const {
  if (std::isinf(max)) {
    const char* op = min_open ? ">" : ">=";
    return integer ? fmt::format("must be {} {}", op, min) : fmt::format("must be a finite value {} {}", op, min);
  }
  return fmt::format("must be in {}", describe());
}

std::string OptionRange::describe() const {
  if (std::isinf(min) && std::isinf(max)) return "any";
  if (std::isinf(max)) return fmt::format("{} {}", min_open ? ">" : ">=", min);
  if (std::isinf(min)) return fmt::format("{} {}", max_open ? "<" : "<=", max);
  return fmt::format("{}{}, {}{}", min_open ? '(' : '[', min, max, max_open ? ')' : ']');
}

SlamOption::Value SlamOption::get(const SlamOptions& o) const {
  auto& options = const_cast<SlamOptions&>(o);  // the accessors only read here
  return std::visit(
      [&](auto* ref) -> Value {
        const auto v = ref(options);
        if constexpr (std::is_same_v<std::remove_const_t<decltype(v)>, double>) {
          if (isAngle()) return degreesOf(v);
        }
        return v;
      },
      ref);
}

void SlamOption::set(SlamOptions& o, const Value& v) const {
  std::visit(
      [&](auto* ref) {
        using T = std::remove_reference_t<decltype(ref(o))>;
        const T* value = std::get_if<T>(&v);
        if (!value) throw invalidArgument("value of the wrong type", {"SlamOptions", 0, std::string(field)});
        if constexpr (std::is_same_v<T, double>) {
          ref(o) = isAngle() ? *value * kDeg : *value;
        } else {
          ref(o) = *value;
        }
      },
      ref);
}

std::optional<std::string> SlamOption::rangeError(const SlamOptions& o) const {
  if (isFlag()) return std::nullopt;
  auto& options = const_cast<SlamOptions&>(o);  // the accessors only read here
  return std::visit(
      [&](auto* ref) -> std::optional<std::string> {
        using T = std::remove_reference_t<decltype(ref(options))>;
        const double v = static_cast<double>(ref(options));
        const double scale = isAngle() ? kDeg : 1.0;  // the range is in degrees, the field in radians
        const OptionRange r{range.min * scale, range.min_open, range.max * scale, range.max_open};
        const bool integer = std::is_integral_v<T>;
        if ((!integer && !std::isfinite(v)) || !r.contains(v)) return range.requirement(integer);
        return std::nullopt;
      },
      ref);
}

const SlamOption* findSlamOption(std::string_view name) {
  for (const SlamOption& o : slamOptionTable())
    if (o.name() == name) return &o;
  return nullptr;
}

std::string formatOptionValue(const SlamOption::Value& v) {
  return std::visit(
      [](auto x) -> std::string {
        if constexpr (std::is_same_v<decltype(x), bool>) return x ? "true" : "false";
        return fmt::format("{}", x);
      },
      v);
}

void SlamOptions::validate() const {
  for (const SlamOption& o : slamOptionTable())
    if (auto why = o.rangeError(*this)) throw invalidArgument(*why, {"SlamOptions", 0, std::string(o.field)});
}

}  // namespace lidar2d::slam
