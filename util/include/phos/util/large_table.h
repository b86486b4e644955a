// Storage for large tables read at random, once per ray or path vertex (a
// big mesh's triangles, its glow, the path tracer's emitter table).
#pragma once

#include <cstddef>
#include <new>
#include <utility>
#include <vector>

namespace phos {

// A std::vector allocator for such tables. From 2 MiB up, storage is
// 2 MiB-aligned and advised as transparent huge pages (madvise
// MADV_HUGEPAGE; Debian's default is to use them only where advised): a read
// at random then needs one TLB entry per 2 MiB instead of per 4 KiB, and a
// table filled afresh every frame takes a page fault per 2 MiB instead of
// per 4 KiB. On the machine measured a dependent random read over 96 MiB
// took 200 to 210 ns on huge pages and 240 to 260 ns without. Embree
// advises its own BVH the same way.
//
// resize() default-initialises (as make_unique_for_overwrite does): a table
// whose every element is written next is not zeroed first on one thread.
// assign(n, value) and resize(n, value) fill as usual.
// Blocks of a multiple of 2 MiB, 2 MiB-aligned, advised as huge pages. A
// freed block is kept (up to 1 GiB in all) for the next request of its exact
// size: the path tracer rebuilds its tables every frame at the same sizes,
// and faulting them in afresh (the kernel zeroing, and compacting memory for
// huge pages) each frame undid much of what huge pages gained. A kept block
// holds its last contents.
void* AllocateHugePageBlock(std::size_t bytes);
void FreeHugePageBlock(void* block, std::size_t bytes);

template <typename T>
class LargeTableAllocator {
 public:
  using value_type = T;
  static constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;
  static std::size_t RoundedBytes(std::size_t bytes) {
    return (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
  }

  LargeTableAllocator() = default;
  template <typename U>
  LargeTableAllocator(const LargeTableAllocator<U>&) {}

  T* allocate(std::size_t n) {
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kHugePageBytes) return static_cast<T*>(::operator new(bytes, std::align_val_t{alignof(T)}));
    return static_cast<T*>(AllocateHugePageBlock(RoundedBytes(bytes)));
  }
  void deallocate(T* p, std::size_t n) {
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kHugePageBytes)
      ::operator delete(p, std::align_val_t{alignof(T)});
    else
      FreeHugePageBlock(p, RoundedBytes(bytes));
  }
  template <typename U>
  void construct(U* p) {
    ::new (static_cast<void*>(p)) U;  // default-, not value-initialised
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <typename U>
  bool operator==(const LargeTableAllocator<U>&) const {
    return true;
  }
};

template <typename T>
using LargeTable = std::vector<T, LargeTableAllocator<T>>;

}  // namespace phos
