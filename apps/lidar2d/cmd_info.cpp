// lidar2d info LOG: one streaming pass over a log, summarised as text or JSON.

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>

#include "commands.hpp"
#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::cli {
namespace {

struct InfoArgs {
  std::string log;
  bool json = false;
  io::ReaderOptions reader;
};

std::string fmtDouble(double v, int digits) { return fmt::format("{:.{}f}", v, digits); }

double deg(double rad) { return rad * 180.0 / std::numbers::pi; }

/// Consecutive scans farther apart in time than this make the log's duration unknown [s].
constexpr double kMaxScanStepS = 86400.0;

nlohmann::json summarise(const InfoArgs& args) {
  // A tilted laser is reported, not refused: info reads it as --allow-tilted would and warns.
  io::ReaderOptions reader = args.reader;
  reader.allow_tilted_laser = true;
  auto source = io::openLog(args.log, reader);
  std::size_t scans = 0, beams_first = 0, beams_min = std::numeric_limits<std::size_t>::max(), beams_max = 0;
  std::size_t with_odom = 0, with_truth = 0, time_repeats = 0, time_backwards = 0;
  std::size_t valid_beams = 0, total_beams = 0;
  double t_first = 0, t_last = 0, t_min = std::numeric_limits<double>::infinity(),
         t_max = -std::numeric_limits<double>::infinity();
  double fov = 0, angle_min = 0, angle_max = 0, range_max = 0, prev_t = 0;
  double odom_len = 0, truth_len = 0;
  double widest_step = 0, step_from = 0, step_to = 0;
  std::size_t step_at = 0;
  std::optional<SE2> prev_odom, prev_truth;
  SE2 T_robot_laser;
  bool upside_down = false;
  double tilt = 0.0;
  while (auto f = source->next()) {
    const std::size_t n = f->scan.size();
    if (scans == 0) {
      beams_first = n;
      fov = f->scan.fieldOfView();
      angle_min = f->scan.angleMin();
      angle_max = f->scan.angleMax();
      range_max = f->scan.rangeMax();
      t_first = f->time;
      T_robot_laser = f->T_robot_laser;
      upside_down = f->laser_upside_down;
      tilt = f->laser_tilt_rad;
    } else {
      if (f->time == prev_t) ++time_repeats;
      if (f->time < prev_t) ++time_backwards;
      if (std::abs(f->time - prev_t) > widest_step) {
        widest_step = std::abs(f->time - prev_t);
        step_from = prev_t;
        step_to = f->time;
        step_at = scans;
      }
    }
    prev_t = f->time;
    t_last = f->time;
    t_min = std::min(t_min, f->time);
    t_max = std::max(t_max, f->time);
    beams_min = std::min(beams_min, n);
    beams_max = std::max(beams_max, n);
    valid_beams += f->scan.numValid();
    total_beams += n;
    if (f->T_odom_robot) {
      ++with_odom;
      if (prev_odom) odom_len += (f->T_odom_robot->translation() - prev_odom->translation()).norm();
      prev_odom = f->T_odom_robot;
    }
    if (f->T_world_robot) {
      ++with_truth;
      if (prev_truth) truth_len += (f->T_world_robot->translation() - prev_truth->translation()).norm();
      prev_truth = f->T_world_robot;
    }
    ++scans;
  }
  const io::SourceNotes notes = source->notes();
  nlohmann::json j;
  j["file"] = args.log;
  j["format"] = io::toString(source->format());
  j["container"] = notes.container;
  j["scans"] = scans;
  j["beams"] = beams_first;
  j["beams_min"] = scans ? beams_min : 0;
  j["beams_max"] = beams_max;
  j["fov_deg"] = deg(fov);
  j["angle_min_deg"] = deg(angle_min);
  j["angle_max_deg"] = deg(angle_max);
  j["range_max_m"] = range_max;
  j["valid_beam_fraction"] = total_beams ? static_cast<double>(valid_beams) / static_cast<double>(total_beams) : 0.0;
  j["t_first"] = t_first;
  j["t_last"] = t_last;
  // A span from a broken clock would be a silent wrong answer: the duration is unknown when every
  // scan has one time, or when consecutive scans are more than a day apart (no laser pauses that
  // long within one log; a negative time written as an unsigned 32-bit number jumps by 2^32 s).
  std::string unknown;
  if (scans > 1 && t_max == t_min)
    unknown = fmt::format("all {} scans have the timestamp {}", scans, t_min);
  else if (widest_step > kMaxScanStepS)
    unknown = fmt::format("the timestamp jumps from {} to {} at scan {} ({:.0f} s)", step_from, step_to, step_at,
                          widest_step);
  if (unknown.empty())
    j["duration_s"] = scans ? t_max - t_min : 0.0;
  else
    j["duration_s"] = nullptr;
  j["duration_unknown"] = unknown;
  j["time_repeats"] = time_repeats;
  j["time_backwards"] = time_backwards;
  j["has_odometry"] = with_odom > 0;
  j["has_truth"] = with_truth > 0;
  j["scans_with_odometry"] = with_odom;
  j["scans_with_truth"] = with_truth;
  j["odometry_path_m"] = odom_len;
  j["truth_path_m"] = truth_len;
  j["laser_mount"] = {T_robot_laser.x(), T_robot_laser.y(), T_robot_laser.theta()};
  j["laser_upside_down"] = upside_down;
  j["laser_tilt_deg"] = deg(tilt);
  j["scan_source"] = notes.scan_source;
  j["lasers"] = notes.lasers;
  j["odometry_source"] = notes.odom_source;
  j["truth_source"] = notes.truth_source;
  // The reader's warnings, with openLog's: timestamps that repeat or go backwards, readings beyond
  // the range max that are not the no-return code.
  nlohmann::json warnings = notes.warnings;
  if (tilt > 0.0 && !args.reader.allow_tilted_laser)
    warnings.push_back(fmt::format("the laser is tilted by {:.1f} deg: the other commands refuse this log unless "
                                   "--allow-tilted (or a --max-tilt above the tilt) is given",
                                   deg(tilt)));
  j["beams_beyond_range_max"] = notes.beams_beyond_range_max;
  j["warnings"] = warnings;
  return j;
}

void printText(const nlohmann::json& j) {
  auto& o = std::cout;
  o << "file:        " << j["file"].get<std::string>() << " (" << j["format"].get<std::string>();
  if (!j["container"].get<std::string>().empty()) o << ": " << j["container"].get<std::string>();
  o << ")\n";
  o << "scans:       " << j["scans"] << " from " << j["scan_source"].get<std::string>() << "\n";
  if (!j["lasers"].empty()) {
    std::string lasers;
    for (const auto& l : j["lasers"]) lasers += (lasers.empty() ? "" : ", ") + l.get<std::string>();
    o << "lasers:      " << lasers << "\n";
  }
  o << "beams:       " << j["beams"];
  if (j["beams_min"] != j["beams_max"]) o << " (varies " << j["beams_min"] << ".." << j["beams_max"] << ")";
  o << ", field of view " << fmtDouble(j["fov_deg"].get<double>(), 2) << " deg ("
    << fmtDouble(j["angle_min_deg"].get<double>(), 2) << " .. " << fmtDouble(j["angle_max_deg"].get<double>(), 2)
    << "), range max " << fmtDouble(j["range_max_m"].get<double>(), 2) << " m, "
    << fmtDouble(100.0 * j["valid_beam_fraction"].get<double>(), 1) << "% of beams valid\n";
  if (j["duration_s"].is_null())
    o << "duration:    unknown: " << j["duration_unknown"].get<std::string>() << " (first ";
  else
    o << "duration:    " << fmtDouble(j["duration_s"].get<double>(), 3) << " s (first ";
  o << fmtDouble(j["t_first"].get<double>(), 6)
    << ", last " << fmtDouble(j["t_last"].get<double>(), 6) << ")\n";
  auto src = [](const nlohmann::json& s) { return s.get<std::string>().empty() ? std::string() : " from " + s.get<std::string>(); };
  o << "odometry:    " << (j["has_odometry"].get<bool>() ? "yes" : "no") << src(j["odometry_source"]);
  if (j["has_odometry"].get<bool>()) o << ", " << fmtDouble(j["odometry_path_m"].get<double>(), 1) << " m travelled";
  o << "\n";
  o << "truth:       " << (j["has_truth"].get<bool>() ? "yes" : "no") << src(j["truth_source"]);
  if (j["has_truth"].get<bool>()) o << ", " << fmtDouble(j["truth_path_m"].get<double>(), 1) << " m travelled";
  o << "\n";
  const auto& m = j["laser_mount"];
  o << "laser mount: x " << fmtDouble(m[0].get<double>(), 3) << " m, y " << fmtDouble(m[1].get<double>(), 3) << " m, theta "
    << fmtDouble(deg(m[2].get<double>()), 2) << " deg";
  if (j["laser_upside_down"].get<bool>()) o << ", upside down (scans mirrored)";
  if (j["laser_tilt_deg"].get<double>() > 0.0)
    o << ", tilted " << fmtDouble(j["laser_tilt_deg"].get<double>(), 1) << " deg (beams projected onto the floor plane)";
  o << "\n";
  for (const auto& w : j["warnings"]) o << "warning:     " << w.get<std::string>() << "\n";
}

}  // namespace

void addInfoCommand(CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  auto* sub = app.add_subcommand("info", "Summarise a log: scans, beams, field of view, duration, odometry/truth");
  sub->add_option("LOG", args->log, "CARMEN log (.log/.clf, plain or .gz), ROS1 bag, ROS2 bag (folder with metadata.yaml, .db3 or .mcap file), or range table folder")->required();
  sub->add_flag("--json", args->json, "print JSON instead of text");
  addReaderOptions(sub, args->reader);
  sub->callback([args] {
    const nlohmann::json j = summarise(*args);
    if (args->json)
      std::cout << j.dump(2) << "\n";
    else
      printText(j);
  });
}

}  // namespace lidar2d::cli
