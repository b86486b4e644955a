#include "phos/util/large_table.h"

#include <mutex>
#include <utility>

#include <sys/mman.h>

namespace phos {
namespace {

constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;
constexpr std::size_t kMaxKeptBytes = std::size_t{1} << 30;

// The kept blocks (AllocateHugePageBlock), released at exit.
class KeptBlocks {
 public:
  ~KeptBlocks() {
    for (const auto& [block, bytes] : blocks_) Release(block);
  }
  void* Take(std::size_t bytes) {
    const std::lock_guard<std::mutex> lock(mutex_);
    for (std::size_t i = 0; i < blocks_.size(); ++i)
      if (blocks_[i].second == bytes) {
        void* block = blocks_[i].first;
        blocks_[i] = blocks_.back();
        blocks_.pop_back();
        kept_bytes_ -= bytes;
        return block;
      }
    return nullptr;
  }
  bool Keep(void* block, std::size_t bytes) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (kept_bytes_ + bytes > kMaxKeptBytes) return false;
    blocks_.emplace_back(block, bytes);
    kept_bytes_ += bytes;
    return true;
  }
  static void Release(void* block) { ::operator delete(block, std::align_val_t{kHugePageBytes}); }

 private:
  std::mutex mutex_;
  std::vector<std::pair<void*, std::size_t>> blocks_;
  std::size_t kept_bytes_ = 0;
};

KeptBlocks& Kept() {
  static KeptBlocks kept;
  return kept;
}

}  // namespace

void* AllocateHugePageBlock(std::size_t bytes) {
  if (void* block = Kept().Take(bytes)) return block;
  void* block = ::operator new(bytes, std::align_val_t{kHugePageBytes});
  madvise(block, bytes, MADV_HUGEPAGE);  // advice only: a kernel without THP ignores it
  return block;
}

void FreeHugePageBlock(void* block, std::size_t bytes) {
  if (!Kept().Keep(block, bytes)) KeptBlocks::Release(block);
}

}  // namespace phos
