#include "lidar2d/io/prefetch.hpp"

#include <utility>

#include "lidar2d/core/read_ahead.hpp"

namespace lidar2d::io {
namespace {

class PrefetchingSource final : public FrameSource {
 public:
  PrefetchingSource(std::unique_ptr<FrameSource> source, std::size_t capacity)
      : source_(std::move(source)),
        path_(source_->path()),
        size_hint_(source_->sizeHint()),
        ahead_([this] { return source_->next(); }, capacity) {}

  std::optional<Frame> next() override { return ahead_.next(); }
  LogFormat format() const override { return source_->format(); }
  // Fixed once the wrapped source is constructed, so reading it from this thread is safe.
  std::optional<std::size_t> sizeHint() const override { return size_hint_; }
  const std::string& path() const override { return path_; }
  // The wrapped source's, once its thread is done with it.
  SourceNotes notes() const override { return ahead_.done() ? source_->notes() : SourceNotes{}; }

 private:
  std::unique_ptr<FrameSource> source_;
  const std::string path_;
  const std::optional<std::size_t> size_hint_;
  ReadAhead<Frame> ahead_;  // last member: its thread reads source_
};

}  // namespace

std::unique_ptr<FrameSource> prefetch(std::unique_ptr<FrameSource> source, std::size_t capacity) {
  return std::make_unique<PrefetchingSource>(std::move(source), capacity);
}

}  // namespace lidar2d::io
