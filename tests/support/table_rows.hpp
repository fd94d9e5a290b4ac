#pragma once
// The whitespace-separated fields of each line of a text output file (trajectories, localize and
// track outputs), for the CLI tests.

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace lidar2d::test {

/// Each non-empty line of `file` not starting with '#', split at whitespace.
inline std::vector<std::vector<std::string>> tableRows(const std::string& file) {
  std::ifstream in(file);
  std::vector<std::vector<std::string>> out;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::vector<std::string> f;
    for (std::string w; ss >> w;) f.push_back(w);
    out.push_back(f);
  }
  return out;
}

}  // namespace lidar2d::test
