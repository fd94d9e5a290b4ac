#pragma once
// Subcommands of the lidar2d CLI. Each adds itself to the app and runs from its CLI11 callback;
// errors are thrown as lidar2d::Error (exit 1) and turned into one line on stderr by main().

#include <CLI/CLI.hpp>
#include <exception>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

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
/// Adds `track`.
void addTrackCommand(CLI::App& app);

/// Adds the reader flags shared by every command that reads a log (--scan-topic, --odom-topic,
/// --carmen-laser, --carmen-poses) bound to `options`.
void addReaderOptions(CLI::App* sub, io::ReaderOptions& options);

/// Prints the warnings a log's reader gathered (`source.notes()`: timestamps that repeat, returns
/// beyond a declared range max, a tilted laser projected, ...), one line each on stderr as
/// "lidar2d: warning: LOG: ...", once the log has been read: a command that processes a log tells
/// the user what `lidar2d info` would, whatever -q says. Returns them (for a JSON summary's
/// `log_warnings`).
std::vector<std::string> warnAboutLog(const std::string& log, const io::FrameSource& source);
/// The printing half of warnAboutLog, for warnings taken from the source earlier.
void printLogWarnings(const std::string& log, const std::vector<std::string>& warnings);

/// The output folders a command created; removed again (those still empty) when the object is
/// destroyed during a failure (an exception in flight), so that a failed command leaves nothing.
class CreatedFolders {
 public:
  CreatedFolders() = default;
  CreatedFolders(CreatedFolders&& o) noexcept : created_(std::move(o.created_)), exceptions_(o.exceptions_) {
    o.created_.clear();
  }
  CreatedFolders& operator=(CreatedFolders&&) = delete;
  CreatedFolders(const CreatedFolders&) = delete;
  ~CreatedFolders();

 private:
  friend CreatedFolders prepareOutputDir(const std::string& path);
  std::vector<std::filesystem::path> created_;
  int exceptions_ = std::uncaught_exceptions();
};

/// Checks, before a command does any work, that it will be able to write the file `path`: creates
/// its missing parent folders (as `slam` creates its output folder) and throws lidar2d::Error (kIo)
/// naming the path when it is a folder, or its folder cannot be created or is not writable. Keep
/// the result alive for the command's run: a failure removes the folders it created.
[[nodiscard]] CreatedFolders prepareOutputFile(const std::string& path);
/// The same for an output folder: creates it (and its parents) when missing.
[[nodiscard]] CreatedFolders prepareOutputDir(const std::string& path);

/// Option checks with readable messages (CLI11's PositiveNumber prints its range up to the largest
/// double, and lets NaN through): a finite number > 0, a finite number >= 0.
CLI::Validator positiveNumber();
CLI::Validator nonNegativeNumber();
/// Adds an option whose value is one of the words of `choices` (case-insensitive), each mapped to
/// its value of T (`value` is a T or a std::optional<T>). --help shows the words ("p2p|p2l|lf|corr"), not CLI11's table
/// of the mapping.
template <class T, class V>
CLI::Option* addChoice(CLI::App* sub, const std::string& flags, V& value,
                       std::vector<std::pair<std::string, T>> choices, const std::string& help) {
  std::string words;
  for (const auto& c : choices) words += (words.empty() ? "" : "|") + c.first;
  return sub->add_option(flags, value, help)
      ->transform(CLI::CheckedTransformer(std::move(choices), CLI::ignore_case).description(""))
      ->type_name(words);
}

/// Adds a finiteness check to every floating-point option of `app` and its subcommands, recursively
/// (CLI11 reads "nan" and "inf" as numbers). Call after adding the subcommands.
void requireFiniteNumbers(CLI::App& app);
/// Rewrites the value names --help shows for every option of `app` and its subcommands, recursively,
/// in words instead of CLI11's parser types and check names: NUMBER, INTEGER, PATH or NAME (TEXT,
/// by the help text), with their bounds ("NUMBER > 0", "NUMBER in 0..45"); names already set
/// ("X,Y,YAW", "p2p|p2l") stay. Call after requireFiniteNumbers.
void showValuesInWords(CLI::App& app);

}  // namespace lidar2d::cli
