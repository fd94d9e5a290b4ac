#include "slam_config.hpp"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <sstream>
#include <variant>

#include "lidar2d/core/error.hpp"

namespace lidar2d::cli {
namespace {

/// `text` as comment lines of at most about `width` characters, each starting with "# ".
std::string commentLines(const std::string& text, std::size_t width = 100) {
  std::istringstream words(text);
  std::string out, line, w;
  while (words >> w) {
    if (!line.empty() && line.size() + 1 + w.size() > width) {
      out += "# " + line + "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + w;
  }
  if (!line.empty()) out += "# " + line + "\n";
  return out;
}

std::string rangeText(const slam::SlamOption& opt) { return opt.isFlag() ? "true or false" : opt.range.describe(); }

}  // namespace

slam::SlamOptions readSlamConfig(const std::string& path) {
  slam::SlamOptions o;
  if (path.empty()) return o;
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw ioError("cannot read the config file", ErrorLocation(path));
  } catch (const YAML::Exception& e) {
    throw badInput(fmt::format("not valid YAML: {}", e.msg),
                   ErrorLocation(path, static_cast<std::size_t>(e.mark.line + 1)));
  }
  if (root.IsNull()) return o;
  if (!root.IsMap()) throw badInput("expected a mapping of option names to values", ErrorLocation(path, 1));
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    const ErrorLocation where(path, static_cast<std::size_t>(kv.first.Mark().line + 1), key);
    const slam::SlamOption* opt = slam::findSlamOption(key);
    if (!opt) throw badInput("unknown option (lidar2d slam --dump-config lists them)", where);
    try {
      // The option's current value only tells the type to read.
      std::visit([&](auto current) { opt->set(o, kv.second.as<decltype(current)>()); }, opt->get(o));
    } catch (const YAML::Exception&) {
      throw badInput("value of the wrong type", where);
    }
    if (auto why = opt->rangeError(o)) throw badInput(*why, where);
  }
  return o;
}

std::string slamConfigYaml(const slam::SlamOptions& o) {
  std::string out =
      "# lidar2d slam options (lidar2d slam LOG -o DIR --config FILE). Each option follows a comment\n"
      "# with its unit, its allowed range and what it does. Angles are in degrees.\n";
  std::string_view group;
  for (const slam::SlamOption& opt : slam::slamOptionTable()) {
    if (opt.group != group) {
      group = opt.group;
      out += fmt::format("\n# --- {} ---\n", group);
    }
    out += commentLines(fmt::format("[{}] {}: {}", opt.unit, rangeText(opt), opt.help));
    out += fmt::format("{}: {}\n", opt.name(), slam::formatOptionValue(opt.get(o)));
  }
  return out;
}

std::string slamOptionsMarkdown(const slam::SlamOptions& o) {
  std::string out = "| name | default | unit | range | meaning |\n|---|---|---|---|---|\n";
  for (const slam::SlamOption& opt : slam::slamOptionTable())
    out += fmt::format("| `{}` | {} | {} | {} | {} |\n", opt.name(), slam::formatOptionValue(opt.get(o)), opt.unit,
                       rangeText(opt), opt.help);
  return out;
}

nlohmann::ordered_json slamOptionsJson(const slam::SlamOptions& o) {
  nlohmann::ordered_json j = nlohmann::ordered_json::object();
  for (const slam::SlamOption& opt : slam::slamOptionTable())
    std::visit([&](auto v) { j[opt.name()] = v; }, opt.get(o));
  return j;
}

}  // namespace lidar2d::cli
