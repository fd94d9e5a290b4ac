// lidar2d command-line program: wires the library's modules together. Exit codes: 0 success,
// 1 bad input or I/O failure (one line on stderr), 2 usage error.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <exception>
#include <opencv2/core/utils/logger.hpp>
#include <iostream>
#include <new>
#include <string>
#include <vector>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"

namespace {

// Edit distance (insertions, deletions, substitutions, and swaps of neighbours: "slma" is one
// step from "slam"), for suggesting the nearest command name.
std::size_t editDistance(const std::string& a, const std::string& b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i)
    for (std::size_t j = 1; j <= b.size(); ++j) {
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[a.size()][b.size()];
}

// CLI11 reports an unknown first word as "A subcommand is required". When the first argument is no
// option and no command, this names it and the nearest command instead; returns false then.
bool knownCommandOrOption(const CLI::App& app, const std::string& word) {
  if (word.empty() || word[0] == '-') return true;
  std::string nearest;
  std::size_t best = std::string::npos;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) {
    if (sub->get_name() == word) return true;
    const std::size_t d = editDistance(word, sub->get_name());
    if (d < best) {
      best = d;
      nearest = sub->get_name();
    }
  }
  std::cerr << "lidar2d: error: unknown command '" << word << "'";
  // More than half the word changed is no longer a typo.
  if (best <= std::max<std::size_t>(1, word.size() / 2)) std::cerr << "; did you mean '" << nearest << "'?";
  std::cerr << " ('lidar2d --help' lists the commands)\n";
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  // OpenCV would print its own warnings (e.g. on an unreadable image) on stderr; errors reach the
  // user as one lidar2d::Error line instead.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  CLI::App app{"lidar2d: scan matching, mapping, localization and SLAM for 2D laser scanners"};
  app.set_version_flag("--version", "lidar2d 0.1.0");
  app.require_subcommand(1);
  app.failure_message(CLI::FailureMessage::help);
  lidar2d::cli::addInfoCommand(app);
  lidar2d::cli::addSimulateCommand(app);
  lidar2d::cli::addPerturbCommand(app);
  lidar2d::cli::addEvalCommand(app);
  lidar2d::cli::addMapCommand(app);
  lidar2d::cli::addPosesCommand(app);
  lidar2d::cli::addMatchCommand(app);
  lidar2d::cli::addSlamCommand(app);
  lidar2d::cli::addDegeneracyCommand(app);
  lidar2d::cli::addLocalizeCommands(app);
  lidar2d::cli::addTrackCommand(app);
  lidar2d::cli::requireFiniteNumbers(app);
  lidar2d::cli::showValuesInWords(app);
  if (argc > 1 && !knownCommandOrOption(app, argv[1])) return 2;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  } catch (const lidar2d::Error& e) {
    std::cerr << "lidar2d: error: " << e.what() << "\n";
    return 1;
  } catch (const std::bad_alloc&) {
    std::cerr << "lidar2d: error: out of memory (input too large?)\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "lidar2d: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
