// Placeholder: replaced by the real command.
#include "commands.hpp"
#include "lidar2d/core/error.hpp"

namespace lidar2d::cli {

void addPerturbCommand(CLI::App& app) {
  auto* sub = app.add_subcommand("perturb", "(not implemented yet)");
  sub->callback([] { throw Error(ErrorKind::kUnsupported, "'perturb' is not implemented yet"); });
}

}  // namespace lidar2d::cli
