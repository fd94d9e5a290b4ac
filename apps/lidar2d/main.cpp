// lidar2d command-line program: wires the library's modules together. Exit codes: 0 success,
// 1 bad input or I/O failure (one line on stderr), 2 usage error.

#include <CLI/CLI.hpp>
#include <exception>
#include <opencv2/core/utils/logger.hpp>
#include <iostream>
#include <new>

#include "commands.hpp"
#include "lidar2d/core/error.hpp"

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
  lidar2d::cli::requireFiniteNumbers(app);
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
