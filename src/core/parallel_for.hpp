#pragma once
// A parallel loop over indices for the library's modules (library-private, not installed).
// Hand-written: the toolchain's std::execution policies need TBB, which the library does not
// depend on, and OpenMP would add a compiler runtime for a few short loops.

#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace lidar2d {

/// Calls f(i) for every i in [0, n) on up to `threads` threads (the caller's included), each
/// taking the next index in turn. Each f(i) must write only its own result (e.g. slot i of a
/// vector), so the outcome is the same on any number of threads. Rethrows the first exception
/// after every thread has finished; the indices not started by then are skipped.
template <typename F>
void parallelFor(std::size_t n, std::size_t threads, F&& f) {
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (std::size_t i; (i = next.fetch_add(1)) < n;) f(i);
    } catch (...) {
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = n;
    }
  };
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < threads && t < n; ++t) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace lidar2d
