#pragma once
// Subcommands of the lidar2d CLI. Each adds itself to the app and runs from its CLI11 callback;
// errors are thrown as lidar2d::Error (exit 1) and turned into one line on stderr by main().

#include <CLI/CLI.hpp>

#include "lidar2d/io/frame_source.hpp"

namespace lidar2d::cli {

void addInfoCommand(CLI::App& app);
void addSimulateCommand(CLI::App& app);
void addPerturbCommand(CLI::App& app);
void addEvalCommand(CLI::App& app);
void addMapCommand(CLI::App& app);
void addPosesCommand(CLI::App& app);
void addMatchCommand(CLI::App& app);
void addSlamCommand(CLI::App& app);
void addDegeneracyCommand(CLI::App& app);
/// Adds `localize-index` and `localize`.
void addLocalizeCommands(CLI::App& app);

/// Adds the reader flags shared by every command that reads a log (--scan-topic, --odom-topic,
/// --carmen-laser, --carmen-poses) bound to `options`.
void addReaderOptions(CLI::App* sub, io::ReaderOptions& options);

/// Option checks with readable messages (CLI11's PositiveNumber prints its range up to the largest
/// double, and lets NaN through): a finite number > 0, a finite number >= 0.
CLI::Validator positiveNumber();
CLI::Validator nonNegativeNumber();
/// Adds a finiteness check to every floating-point option of `app` and its subcommands, recursively
/// (CLI11 reads "nan" and "inf" as numbers). Call after adding the subcommands.
void requireFiniteNumbers(CLI::App& app);

}  // namespace lidar2d::cli
