// Placeholder: replaced by the real command.
#include "commands.hpp"
#include "lidar2d/core/error.hpp"

namespace lidar2d::cli {

void addSimulateCommand(CLI::App& app) {
  auto* sub = app.add_subcommand("simulate", "(not implemented yet)");
  sub->callback([] { throw Error(ErrorKind::kUnsupported, "'simulate' is not implemented yet"); });
}

}  // namespace lidar2d::cli
