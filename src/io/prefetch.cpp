#include "lidar2d/io/prefetch.hpp"

#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>
#include <utility>

namespace lidar2d::io {
namespace {

class PrefetchingSource final : public FrameSource {
 public:
  PrefetchingSource(std::unique_ptr<FrameSource> source, std::size_t capacity)
      : source_(std::move(source)),
        capacity_(capacity == 0 ? 1 : capacity),
        path_(source_->path()),
        size_hint_(source_->sizeHint()) {
    worker_ = std::thread([this] { run(); });
  }
  ~PrefetchingSource() override {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    worker_.join();
  }

  std::optional<Frame> next() override {
    std::unique_lock lock(mutex_);
    cv_.wait(lock, [this] { return !queue_.empty() || done_; });
    if (!queue_.empty()) {
      Frame f = std::move(queue_.front());
      queue_.pop_front();
      lock.unlock();
      cv_.notify_all();
      return f;
    }
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
    return std::nullopt;
  }
  LogFormat format() const override { return source_->format(); }
  // Fixed once the wrapped source is constructed, so reading it from this thread is safe.
  std::optional<std::size_t> sizeHint() const override { return size_hint_; }
  const std::string& path() const override { return path_; }
  SourceNotes notes() const override {
    std::lock_guard lock(mutex_);
    return done_ ? source_->notes() : SourceNotes{};
  }

 private:
  void run() {
    try {
      while (true) {
        std::optional<Frame> f = source_->next();
        std::unique_lock lock(mutex_);
        if (!f) break;
        cv_.wait(lock, [this] { return queue_.size() < capacity_ || stop_; });
        if (stop_) break;
        queue_.push_back(std::move(*f));
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

  std::unique_ptr<FrameSource> source_;
  const std::size_t capacity_;
  const std::string path_;
  const std::optional<std::size_t> size_hint_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Frame> queue_;
  std::exception_ptr error_;
  bool done_ = false;
  bool stop_ = false;
  std::thread worker_;
};

}  // namespace

std::unique_ptr<FrameSource> prefetch(std::unique_ptr<FrameSource> source, std::size_t capacity) {
  return std::make_unique<PrefetchingSource>(std::move(source), capacity);
}

}  // namespace lidar2d::io
