#pragma once
/// @file
/// Runs a producer on a background thread, up to `capacity` items ahead of the consumer: the
/// producer's work (parsing a log, preparing scans) overlaps with the consumer's on the other core.

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

namespace lidar2d {

template <class T>
class ReadAhead {
 public:
  /// Starts calling `produce` on a background thread until it returns std::nullopt (the end) or
  /// throws, keeping at most `capacity` (>= 1) items queued.
  ReadAhead(std::function<std::optional<T>()> produce, std::size_t capacity)
      : produce_(std::move(produce)), capacity_(capacity == 0 ? 1 : capacity), worker_([this] { run(); }) {}
  /// Stops the producer (after the item it is working on) and joins its thread.
  ~ReadAhead() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    worker_.join();
  }
  ReadAhead(const ReadAhead&) = delete;
  ReadAhead& operator=(const ReadAhead&) = delete;

  /// The next item in the producer's order; std::nullopt at the end. An exception the producer
  /// threw is rethrown by the call that reaches it.
  std::optional<T> next() {
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [this] { return !queue_.empty() || done_; });
    if (!queue_.empty()) {
      T item = std::move(queue_.front());
      queue_.pop_front();
      lock.unlock();
      cv_.notify_all();
      return item;
    }
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
    return std::nullopt;
  }
  /// True once the producer has finished (reached the end, thrown, or been stopped).
  bool done() const {
    std::lock_guard lock(mutex_);
    return done_;
  }

 private:
  void run() {
    try {
      while (true) {
        std::optional<T> item = produce_();
        std::unique_lock lock(mutex_);
        if (!item) break;
        cv_.wait(lock, [this] { return queue_.size() < capacity_ || stop_; });
        if (stop_) break;
        queue_.push_back(std::move(*item));
        lock.unlock();
        cv_.notify_all();
      }
    } catch (...) {
      std::lock_guard lock(mutex_);
      error_ = std::current_exception();
    }
    {
      std::lock_guard lock(mutex_);
      done_ = true;
    }
    cv_.notify_all();
  }

  std::function<std::optional<T>()> produce_;
  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<T> queue_;
  std::exception_ptr error_;
  bool done_ = false;
  bool stop_ = false;
  std::thread worker_;  // last member: starts once the others exist
};

}  // namespace lidar2d
