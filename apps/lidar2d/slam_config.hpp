#pragma once
// The SLAM options as the CLI reads and writes them: YAML config files, `lidar2d slam
// --dump-config` (YAML or a Markdown table) and the `options` object of summary.json. Every one of
// them iterates slam::kSlamOptionTable, the options' one declaration.

#include <nlohmann/json.hpp>
#include <string>

#include "lidar2d/slam/slam_options.hpp"

namespace lidar2d::cli {

/// The defaults overridden by the flat YAML mapping of option names to values in `path` (angles in
/// degrees); the defaults when `path` is empty. An unreadable file, invalid YAML, an unknown name, a
/// value of the wrong type or out of its range is a `lidar2d::Error` naming the file, line and key.
slam::SlamOptions readSlamConfig(const std::string& path);

/// Every option of `o` as a YAML config file that readSlamConfig reads back to `o`: grouped, each
/// preceded by a comment with its unit, allowed range and meaning.
std::string slamConfigYaml(const slam::SlamOptions& o);

/// The options table of docs/slam.md: name, default (the value in `o`), unit, range, meaning.
std::string slamOptionsMarkdown(const slam::SlamOptions& o);

/// Every option of `o` by its YAML name, in its unit (summary.json's `options`).
nlohmann::ordered_json slamOptionsJson(const slam::SlamOptions& o);

}  // namespace lidar2d::cli
