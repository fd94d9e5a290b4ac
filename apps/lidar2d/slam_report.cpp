#include "slam_report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "lidar2d/slam/slam.hpp"
#include "map_output.hpp"

namespace lidar2d::cli {
namespace {

// Base64 for the data: URI of the embedded PNG. Written here because none of the project's
// dependencies exposes an encoder (OpenCV's is internal); it is the RFC 4648 alphabet with padding.
std::string base64(const std::vector<std::uint8_t>& in) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const std::uint32_t v = (std::uint32_t{in[i]} << 16) | (std::uint32_t{in[i + 1]} << 8) | in[i + 2];
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < in.size()) {
    std::uint32_t v = std::uint32_t{in[i]} << 16;
    if (i + 1 < in.size()) v |= std::uint32_t{in[i + 1]} << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < in.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '&':
        out += "&amp;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

}  // namespace

std::string slamReportHtml(const ReportInput& in) {
  const OccupancyImage& map = in.map;
  const double res = map.resolution();
  const SE2 T_map_world = map.origin().inverse();
  const int W = map.width(), H = map.height();
  // World point -> image pixel (row 0 at the top).
  auto px = [&](const Eigen::Vector2d& p_world) {
    const Eigen::Vector2d m = T_map_world * p_world;
    return Eigen::Vector2d(m.x() / res, static_cast<double>(H) - m.y() / res);
  };
  const double stroke = std::max(1.0, std::max(W, H) / 600.0);

  std::ostringstream svg;
  svg << fmt::format(R"(<svg class="overlay" viewBox="0 0 {} {}" preserveAspectRatio="none" xmlns="http://www.w3.org/2000/svg">)", W, H);
  // Trajectory of every scan, one line per session (a resumed map's sessions are not joined).
  for (std::size_t i = 0; i < in.trajectory.size(); ++i) {
    const std::size_t session = in.trajectory[i].session;
    if (i == 0 || session != in.trajectory[i - 1].session)
      svg << fmt::format(R"(<polyline id="{}" fill="none" stroke="#1f77b4" stroke-width="{:.2f}" points=")",
                         i == 0 ? std::string("trajectory") : fmt::format("trajectory-session{}", session + 1), stroke);
    const auto p = px(in.trajectory[i].T_world_robot.translation());
    svg << fmt::format("{:.1f},{:.1f} ", p.x(), p.y());
    if (i + 1 == in.trajectory.size() || in.trajectory[i + 1].session != session) svg << "\"/>\n";
  }
  const auto& nodes = in.slam.nodes();
  // Loop closures: accepted green, rejected red (dashed).
  std::size_t accepted = 0, rejected = 0;
  for (const auto& c : in.slam.constraints()) {
    if (c.kind != slam::Constraint::Kind::kLoop) continue;
    if (c.accepted && !c.searched) continue;  // routine link-following constraints would hide the map
    const auto a = px(nodes[c.from].T_world_robot.translation());
    const auto b = px(nodes[c.to].T_world_robot.translation());
    (c.accepted ? accepted : rejected)++;
    svg << fmt::format(R"(<line class="{}" x1="{:.1f}" y1="{:.1f}" x2="{:.1f}" y2="{:.1f}" stroke="{}" stroke-width="{:.2f}"{}/>)",
                       c.accepted ? (c.descriptor ? "loop-descriptor" : "loop") : "loop-rejected", a.x(), a.y(), b.x(), b.y(),
                       c.accepted ? (c.descriptor ? "#9467bd" : "#2ca02c") : "#d62728",
                       stroke, c.accepted ? "" : R"( stroke-dasharray="4 3")")
        << "\n";
  }
  // Degenerate stretches: nodes whose match could not pin a direction, with that direction.
  std::size_t degenerate = 0;
  for (const auto& n : nodes) {
    if (!n.degenerate) continue;
    ++degenerate;
    const auto p = px(n.T_world_robot.translation());
    const double a = n.T_world_robot.theta() + n.degenerate_dir_rad;
    const double L = 0.5 / res;
    svg << fmt::format(R"(<line class="degenerate" x1="{:.1f}" y1="{:.1f}" x2="{:.1f}" y2="{:.1f}" stroke="#ff7f0e" stroke-width="{:.2f}"/>)",
                       p.x() - L * std::cos(a), p.y() + L * std::sin(a), p.x() + L * std::cos(a), p.y() - L * std::sin(a),
                       2 * stroke)
        << "\n";
  }
  svg << "</svg>";

  // Time per scan plot.
  std::ostringstream plot;
  const double n_scans = static_cast<double>(std::max<std::size_t>(in.trajectory.size(), 2) - 1);
  double tmax = 1e-6;
  for (const auto& e : in.trajectory) tmax = std::max(tmax, e.seconds * 1e3);
  const double PW = 800, PH = 200;
  plot << fmt::format(R"(<svg id="time-plot" viewBox="0 0 {} {}" width="100%" xmlns="http://www.w3.org/2000/svg">)", PW + 90, PH + 30);
  plot << fmt::format(R"(<rect x="80" y="0" width="{}" height="{}" fill="#fafafa" stroke="#999"/>)", PW, PH);
  plot << fmt::format(R"(<polyline fill="none" stroke="#1f77b4" stroke-width="1" points=")");
  for (std::size_t i = 0; i < in.trajectory.size(); ++i)
    plot << fmt::format("{:.1f},{:.1f} ", 80 + PW * static_cast<double>(i) / n_scans,
                        PH - PH * in.trajectory[i].seconds * 1e3 / tmax);
  plot << "\"/>";
  plot << fmt::format(R"(<text x="75" y="12" text-anchor="end" font-size="11">{:.1f} ms</text>)", tmax);
  plot << fmt::format(R"(<text x="75" y="{}" text-anchor="end" font-size="11">0</text>)", PH);
  plot << fmt::format(R"(<text x="{}" y="{}" text-anchor="middle" font-size="11">scan (1 .. {})</text>)", 80 + PW / 2, PH + 20,
                      in.trajectory.size());
  plot << "</svg>";

  const auto png = encodeMapPng(map, "report.html");
  const auto& j = in.summary;
  std::ostringstream html;
  html << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>lidar2d slam: "
       << escape(in.log) << "</title>\n"
       << R"(<style>
body{font-family:sans-serif;margin:1.5em;max-width:1100px;color:#222}
.mapbox{position:relative;display:inline-block;width:100%;max-width:1000px;border:1px solid #999}
.mapbox img{display:block;width:100%;image-rendering:pixelated}
.overlay{position:absolute;left:0;top:0;width:100%;height:100%}
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 8px;text-align:left}
.legend span{display:inline-block;width:1.5em;height:0.3em;margin:0 0.3em 0.2em 1em;vertical-align:middle}
</style></head><body>
)";
  html << "<h1>lidar2d slam</h1>\n<p id=\"log\">" << escape(in.log) << "</p>\n";
  html << "<table id=\"summary\">\n";
  auto row = [&](const std::string& k, const std::string& v) { html << "<tr><th>" << k << "</th><td>" << v << "</td></tr>\n"; };
  row("scans", fmt::format("{}", j.value("scans", 0)));
  if (j.contains("sessions") && j["sessions"].size() > 1) {
    std::string logs;
    for (const auto& x : j["sessions"])
      logs += fmt::format("{}{} ({} scans)", logs.empty() ? "" : "; ", escape(x.value("log", "")), x.value("scans", 0));
    row("sessions", fmt::format("{}, resumed from a saved state: {}", j["sessions"].size(), logs));
  }
  row("nodes / submaps", fmt::format("{} / {}", j.value("nodes", 0), j.value("submaps", 0)));
  row("odometry", j.value("used_odometry", false) ? "used as the prediction" : "not used (scan matching only)");
  row("scans matched / unmatched / correlative fallbacks",
      fmt::format("{} / {} / {}", j.value("matched", 0), j.value("unmatched", 0), j.value("correlative_fallbacks", 0)));
  row("moving objects left out", fmt::format("{} returns in {} scans (people walking with the robot or crossing its "
                                             "path; drop_moving_objects)",
                                             j.value("moving_points", 0), j.value("scans_with_moving_points", 0)));
  row("degenerate scans", fmt::format("{} ({} nodes, orange on the map)", j.value("degenerate_scans", 0), degenerate));
  row("loop closures", fmt::format("{} accepted, {} rejected; {} searched by branch and bound (drawn: {} accepted, {} rejected); "
                                   "{} down-weighted by the pose graph (the rest of the graph contradicts them)",
                                   j.value("loop_closures_accepted", 0), j.value("loop_closures_rejected", 0),
                                   j.value("loop_searches", 0), accepted, rejected, j.value("loop_closures_downweighted", 0)));
  row("loop closures by descriptors (large drift)",
      fmt::format("{} accepted; {} look-ups, {} hypotheses verified, {:.2f} s (purple on the map)",
                  j.value("descriptor_closures_accepted", 0), j.value("descriptor_queries", 0),
                  j.value("descriptor_hypotheses", 0), j.value("descriptor_seconds", 0.0)));
  row("pose-graph optimisations", fmt::format("{} ({:.2f} s)", j.value("optimizations", 0), j.value("optimization_s", 0.0)));
  row("time", fmt::format("read + slam {:.2f} s, map {:.2f} s", j.value("slam_s", 0.0),
                          j.value("map_s", 0.0)));
  row("time per scan", fmt::format("mean {:.2f} ms, median {:.2f} ms, p95 {:.2f} ms, p99 {:.2f} ms, max {:.1f} ms",
                                   j.value("ms_per_scan_mean", 0.0), j.value("ms_per_scan_median", 0.0),
                                   j.value("ms_per_scan_p95", 0.0), j.value("ms_per_scan_p99", 0.0),
                                   j.value("ms_per_scan_max", 0.0)));
  row("fragments", fmt::format("{} (stretches between lost tracks not tied together by a loop closure; 1: one map); "
                               "{} lost tracks relocalized in the earlier map; "
                               "odometry overruled {} estimates made without scan evidence",
                               j.value("fragments", 0), j.value("relocalizations", 0), j.value("odometry_wins", 0)));
  row("motion prior", fmt::format("{} matches taken against it on strong scan evidence, {} contradicting it rejected",
                                  j.value("prior_overridden", 0), j.value("prior_kept", 0)));
  if (j.value("used_odometry", false)) {
    const bool applied = j.contains("options") && j["options"].value("scale_odometry", false);
    row("odometry scale",
        j.value("odometry_scale_evidence_m", 0.0) >= slam::kOdometryScaleMinEvidenceM
            ? fmt::format("the scans measured {:.3f} m per metre of odometry over the last {:.0f} m of steps they "
                          "pinned; {}",
                          j.value("odometry_scale", 1.0), j.value("odometry_scale_evidence_m", 0.0),
                          applied ? "odometry distances scaled by it" : "not applied (scale_odometry)")
            : fmt::format("not measured: {:.0f} m of steps the scans pinned, {:.0f} m needed",
                          j.value("odometry_scale_evidence_m", 0.0), slam::kOdometryScaleMinEvidenceM));
  }
  if (j.value("used_odometry", false)) {
    // How good the odometry is against the scan matching, as the loop closures' cycles measure it
    // (docs/slam.md, Pose graph): what a user tuning odometry_sigma_* would want to know.
    const std::size_t cycles = j.value("loop_cycles", std::size_t{0});
    row("odometry against the matches",
        cycles == 0 ? std::string("not measured: no loop closure over 5 node steps or more with odometry all along")
                    : fmt::format("over {} loop closures' cycles, per node step: odometry {:.3f} degrees and {:.4f} m, "
                                  "scan matches {:.3f} degrees and {:.4f} m; {}",
                                  cycles, j.value("cycle_odometry_deg", 0.0), j.value("cycle_odometry_m", 0.0),
                                  j.value("cycle_front_end_deg", 0.0), j.value("cycle_front_end_m", 0.0),
                                  j.value("odometry_weighted_by_cycles", false)
                                      ? "the final graph weighed the odometry links by it"
                                      : "the odometry links kept their own weights"));
  }
  row("map", fmt::format("{} x {} cells of {} m", W, H, res));
  html << "</table>\n";
  html << "<h2>Map and trajectory</h2>\n<p class=\"legend\"><span style=\"background:#1f77b4\"></span>trajectory"
          "<span style=\"background:#2ca02c\"></span>loop closure found by search"
          "<span style=\"background:#9467bd\"></span>... through the descriptors"
          "<span style=\"background:#d62728\"></span>rejected closure"
          "<span style=\"background:#ff7f0e\"></span>degenerate direction</p>\n";
  html << "<div class=\"mapbox\"><img id=\"map\" alt=\"occupancy map\" src=\"data:image/png;base64," << base64(png)
       << "\">" << svg.str() << "</div>\n";
  html << "<h2>Time per scan</h2>\n" << plot.str() << "\n";
  // What the log's reader warned of (summary.json's log_warnings, also on stderr): a user who only
  // opens the report still learns that the log drops returns or repeats its timestamps.
  if (const auto w = j.find("log_warnings"); w != j.end() && w->is_array() && !w->empty()) {
    html << "<h2>Log warnings</h2>\n<ul id=\"log-warnings\">\n";
    for (const auto& line : *w) html << "<li>" << escape(line.get<std::string>()) << "</li>\n";
    html << "</ul>\n";
  }
  html << "<h2>Events</h2>\n";
  const auto& events = in.slam.events();
  if (events.empty()) {
    html << "<p id=\"events\">None: no gaps, no time going backwards, no missing or jumping odometry, no lost tracking.</p>\n";
  } else {
    html << "<table id=\"events\"><tr><th>scan</th><th>time [s]</th><th>what</th></tr>\n";
    const std::size_t shown = std::min<std::size_t>(events.size(), 500);
    for (std::size_t i = 0; i < shown; ++i)
      html << fmt::format("<tr><td>{}</td><td>{:.3f}</td><td>{}</td></tr>\n", events[i].frame_index, events[i].time,
                          escape(events[i].what));
    html << "</table>\n";
    if (shown < events.size()) html << fmt::format("<p>... and {} more (summary.json lists all).</p>\n", events.size() - shown);
  }
  html << "</body></html>\n";
  return html.str();
}

}  // namespace lidar2d::cli
